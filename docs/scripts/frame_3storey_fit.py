"""Exploration: fit an npz of docs/scripts/frame_3storey_run.py by the step response's modal form and compare with the frame model (docs/portal_frame.md section 11)."""
import sys, numpy as np
sys.path.insert(0, "tests/verification")
from scipy.optimize import least_squares
import frame2d_model as F
d = np.load(sys.argv[1]); t, u = d["t"], d["u"]
m = F.from_scene("cases/frame_3storey.toml"); T = m.modes(3)[0]
def basis(w): return 1 - np.cos(np.outer(t, w))
def res(w):
    B = basis(w); c, *_ = np.linalg.lstsq(B, u, rcond=None); return (B @ c - u).ravel()
w0 = 2*np.pi/T
sol = least_squares(res, w0)
B = basis(sol.x); c, *_ = np.linalg.lstsq(B, u, rcond=None)
print("t_end", t[-1], "T fit", 2*np.pi/sol.x, "frame", T, "ratio", (2*np.pi/sol.x)/T)
print("rms residual / max", np.sqrt(np.mean(res(sol.x)**2))/np.abs(u).max())
for k, n in enumerate(("c0_f1","c0_f2","c0_f3")):
    uf = m.step_response(t, m.node_dofs[n][0])
    j = np.argmax(u[:, k]); jf = np.argmax(uf)
    print(n, "MPM max %.4f at %.3f, frame %.4f at %.3f, ratio %.4f" % (u[j,k], t[j], uf[jf], t[jf], u[j,k]/uf[jf]),
          "rms gap/max %.4f" % (np.sqrt(np.mean((u[:,k]-uf)**2))/uf.max()))
