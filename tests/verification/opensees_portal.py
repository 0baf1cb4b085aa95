"""Cross-check of frame2d_model.py with OpenSeesPy (a script, not a test: OpenSeesPy is not a
dependency of pmpm).

The portal of cases/portal_frame.toml with the idealisation of frame2d_model.py's
``joints="scissors"`` (Krawinkler's panel), built in
OpenSees: members of 8 ``ElasticTimoshenkoBeam`` elements (shear area d t_w, consistent mass),
rigid offsets into the joints as stiff massless ``elasticBeamColumn`` links, the joint panel as
a rotational ``zeroLength`` spring G d_c t_w d_b between the column node and the beams' node
(``equalDOF`` in translation), panel and stub masses at the joints; fixed or pinned bases.
Prints T1 to T3 and the static drift under the 444.82 kN load beside frame2d_model's.

(The rigid offsets are links, not ``geomTransf -jntOffset``: with joint offsets the
ElasticTimoshenkoBeam of OpenSeesPy 3.7.1.2 gives a static drift below the Euler-Bernoulli
element's, i.e. it does not honour them; ``elasticBeamColumn`` with ``-jntOffset`` agrees with
the links to 4 digits.)

Run (OpenSeesPy's Linux wheel bundles libgfortran.so.4 and BLAS, preloaded here)::

    pip install --target /tmp/ops openseespylinux==3.7.1.2 openseespy --no-deps
    OPENSEES_TARGET=/tmp/ops python tests/verification/opensees_portal.py
"""
import ctypes
import math
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
E, NU, RHO = 207e9, 0.3, 7850.0
COL = dict(d=0.33325, tw=0.018034, A=0.022774, I=4.4537e-4)
BEAM = dict(d=0.40284, tw=0.007493, A=0.0068387, I=1.8647e-4)
H, L, N, LOAD = 3.658, 6.096, 8, 444820.0


def _opensees():
    target = os.environ.get("OPENSEES_TARGET")
    if target:
        lib = os.path.join(target, "openseespylinux", "lib")
        for name in ("libquadmath.so.0", "libgfortran.so.4", "libgomp.so.1", "libblas.so.3", "liblapack.so.3"):
            ctypes.CDLL(os.path.join(lib, name), mode=ctypes.RTLD_GLOBAL)
        sys.path.insert(0, target)
    import openseespy.opensees as ops
    return ops


def portal(ops, support):
    """(periods (s) of the first three modes, static drift (m) of the loaded joint)."""
    G = E / (2 * (1 + NU))
    ops.wipe()
    ops.model("basic", "-ndm", 2, "-ndf", 3)
    ops.geomTransf("Linear", 1)
    count = {"node": 0, "ele": 0}

    def node(x, y):
        count["node"] += 1
        ops.node(count["node"], x, y)
        return count["node"]

    def element(*args):
        count["ele"] += 1
        ops.element(args[0], count["ele"], *args[1:])

    def member(a, b, sec, off_a, off_b):
        xa, ya = ops.nodeCoord(a)
        xb, yb = ops.nodeCoord(b)
        ends = []
        for n0, (dx, dy) in ((a, off_a), (b, off_b)):
            if (dx, dy) == (0.0, 0.0):
                ends.append(n0)
                continue
            x, y = ops.nodeCoord(n0)
            m = node(x + dx, y + dy)
            element("elasticBeamColumn", n0, m, sec["A"] * 1e4, E, sec["I"] * 1e4, 1)
            ends.append(m)
        (x0, y0), (x1, y1) = ops.nodeCoord(ends[0]), ops.nodeCoord(ends[1])
        ids = [ends[0]] + [node(x0 + (x1 - x0) * k / N, y0 + (y1 - y0) * k / N) for k in range(1, N)] + [ends[1]]
        for i, j in zip(ids, ids[1:]):
            element("ElasticTimoshenkoBeam", i, j, E, G, sec["A"], sec["I"], sec["d"] * sec["tw"], 1,
                    "-mass", RHO * sec["A"], "-cMass")

    bases = [node(0.0, 0.0), node(L, 0.0)]
    joints = [node(0.0, H), node(L, H)]
    panels = [node(0.0, H), node(L, H)]
    for base, joint in zip(bases, joints):
        member(base, joint, COL, (0.0, 0.0), (0.0, -BEAM["d"] / 2))
    member(panels[0], panels[1], BEAM, (COL["d"] / 2, 0.0), (-COL["d"] / 2, 0.0))
    ops.uniaxialMaterial("Elastic", 1, G * COL["d"] * COL["tw"] * BEAM["d"])
    for joint, panel in zip(joints, panels):
        ops.equalDOF(joint, panel, 1, 2)
        element("zeroLength", joint, panel, "-mat", 1, "-dir", 3)
        mass = RHO * COL["A"] * BEAM["d"]   # the panel (d_b / 2 below the node) and the stub above
        ops.mass(joint, mass, mass, 0.0)
    for base in bases:
        ops.fix(base, 1, 1, 1 if support == "fixed" else 0)
    periods = [2 * math.pi / math.sqrt(w2) for w2 in ops.eigen(3)]
    ops.timeSeries("Constant", 1)
    ops.pattern("Plain", 1, 1)
    ops.load(joints[0], LOAD, 0.0, 0.0)
    for cmd, arg in (("system", "FullGeneral"), ("numberer", "Plain"), ("constraints", "Transformation"),
                     ("algorithm", "Linear")):
        getattr(ops, cmd)(arg)
    ops.integrator("LoadControl", 1.0)
    ops.analysis("Static")
    ops.analyze(1)
    return periods, ops.nodeDisp(joints[0], 1)


def main():
    ops = _opensees()
    sys.path.insert(0, HERE)
    import frame2d_model
    case = os.path.join(HERE, "..", "..", "cases", "portal_frame.toml")
    for support in ("fixed", "pinned"):
        periods, drift = portal(ops, support)
        model = frame2d_model.from_scene(case, supports=support, joints="scissors")
        ours = model.modes(3)[0]
        ours_drift = model.static()[model.node_dofs["upper_left_joint"][0]]
        print(f"{support}: OpenSees T = {', '.join(f'{t * 1e3:.3f}' for t in periods)} ms, drift "
              f"{drift * 1e3:.4f} mm; frame2d_model T = {', '.join(f'{t * 1e3:.3f}' for t in ours)} ms, "
              f"drift {ours_drift * 1e3:.4f} mm")


if __name__ == "__main__":
    main()
