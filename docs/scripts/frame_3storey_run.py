"""Exploration: run the three-storey frame's elastic variant at cell size H (argv: H T_END EVERY PPC); writes frame_3storey_H_PPC.npz (docs/portal_frame.md section 11)."""
import sys, time, dataclasses, numpy as np
from mpi4py import MPI
from pmpm.core.solver import Solver
from pmpm.io.tracking import Tracker
from pmpm.scene.config import apply_overrides, parse_scene, read_toml
h = float(sys.argv[1]); t_end = float(sys.argv[2]); every = int(sys.argv[3]) if len(sys.argv) > 3 else 10
scene_path = "cases/frame_3storey.toml"
data = read_toml(scene_path)
data = apply_overrides(data, data["variants"]["elastic"], "variants.elastic")
ppc = int(sys.argv[4]) if len(sys.argv) > 4 else 2
data["particles_per_cell"] = ppc
data["grid"] = dict(data["grid"], origin=[-0.6, 0.0], cell_size=h, cells=[int(round(19.6 / h)), int(round(12.8 / h))])
scene = dataclasses.replace(parse_scene(data, scene_path), variant="elastic")
s = Solver(scene, MPI.COMM_SELF)
names = ["c0_f1", "c0_f2", "c0_f3"]
tr = Tracker([t for t in scene.output.track if t.name in names], s)
print("particles", len(s.particles["x"]))
t, u = [], []
w = time.time()
while s.t < t_end:
    s.step()
    if s.step_count % every == 0:
        t.append(s.t); u.append(tr.sample()[:, 0].copy())
print("steps", s.step_count, "wall", time.time() - w, "dt", s.t / s.step_count)
np.savez(f"frame_3storey_{h}_{ppc}.npz", t=np.array(t), u=np.array(u))
