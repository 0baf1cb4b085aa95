"""argparse types of the benchmark options (a bad value is a one-line error, exit 2)."""
import argparse
import math
import os

__all__ = ["MAX_COUNT", "MATERIALS", "FRAME_CASE", "VARIANT", "positive", "finite_positive", "ranks_arguments",
           "FRAME3_CASE", "profile_arguments"]


#: largest count a benchmark option takes (particles, steps, repeats): 10^9 particles already
#: need ~1 TB; a larger number is a typo (10^15) and would fail inside numpy, not here
MAX_COUNT = 10 ** 9


def positive(text):
    """argparse type: an integer from 1 to MAX_COUNT (a bad value is a one-line error, exit 2)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1 (got {value})")
    if value > MAX_COUNT:
        raise argparse.ArgumentTypeError(f"must be at most {MAX_COUNT:.0e} (got {value:.3g})")
    return value


def finite_positive(text):
    """argparse type: a finite float > 0 and at most 1e15 (inf and nan refused)."""
    import math
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (math.isfinite(value) and 0 < value <= 1e15):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0 and at most 1e15 (got {text!r})")
    return value


#: the block's materials (pmpm.benchmarks.block), by the name of ``--material``
MATERIALS = {
    "elastic": {"type": "linear_elastic", "E": 200e9, "nu": 0.3, "density": 7850.0},
    "linear_elastic": {"type": "linear_elastic", "E": 200e9, "nu": 0.3, "density": 7850.0},
    "smooth_vonmises": {"type": "smooth_vonmises", "E": 200e9, "nu": 0.3, "density": 7850.0,
                        "yield_stress": 250e6, "hardening": 0.05, "smoothness": 10.0},
    "bilinear_vonmises": {"type": "bilinear_vonmises", "E": 200e9, "nu": 0.3, "density": 7850.0,
                          "yield_stress": 250e6, "hardening": 0.05},
    # hyperelastic with the steel's small-strain constants: the same block, the same CFL step
    "neo_hookean": {"type": "neo_hookean", "E": 200e9, "nu": 0.3, "density": 7850.0},
}

#: the main job's scene and the variant timed
FRAME_CASE = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                          "cases", "portal_frame.toml")
VARIANT = "elastic"
#: the three-storey frame, the scene ``pmpm bench profile`` times by default
FRAME3_CASE = os.path.join(os.path.dirname(FRAME_CASE), "frame_3storey.toml")


def ranks_arguments(p):
    """The options of ``pmpm bench ranks``."""
    p.add_argument("--steps", type=positive, default=2000,
                   help="steps of each run (default 2000, about 0.017 s of the frame's 0.25 s)")
    p.add_argument("--repeat", type=positive, default=5, help="runs of each rank count (default 5)")
    p.add_argument("--ranks", type=positive, nargs="+", default=[1, 2],
                   help="rank counts compared (default 1 2)")
    p.add_argument("--load", choices=["both", "none", "busy"], default="both",
                   help="without a background load, under one, or both (default both)")
    p.add_argument("--bind", choices=["core", "none"], default="core",
                   help="mpirun --bind-to (default core, as the main job's command)")
    p.add_argument("--no-output", action="store_true",
                   help="run the solver alone (no files, no histories) instead of the whole run")
    p.add_argument("--phases", action="store_true",
                   help="time the phases of the step on every rank instead (solver only)")
    p.add_argument("--case", default=FRAME_CASE,
                   help="scene file timed (default the main job's cases/portal_frame.toml); a scene "
                        "whose output paths are relative runs in a temporary folder")
    p.add_argument("--variant", default=VARIANT, help=f"its variant (default {VARIANT})")
    p.add_argument("--count-calls", action="store_true",
                   help="also count the MPI calls per step (a PMPI shim built with mpicc)")


def profile_arguments(p):
    """The options of ``pmpm bench profile``."""
    p.add_argument("case", nargs="?", default=FRAME3_CASE,
                   help="scene file (default cases/frame_3storey.toml of this checkout)")
    p.add_argument("--variant", default=None,
                   help="its variant (default the scene's first: the frame's elastic)")
    p.add_argument("--steps", type=positive, default=None,
                   help="steps of each run of the scene (default: one frame interval of the scene)")
    p.add_argument("--rounds", type=positive, default=5, help="interleaved rounds (default 5)")
    p.add_argument("--particles", type=positive, default=200_000,
                   help="particles of the reference block (default 200000)")
    p.add_argument("--block-steps", type=positive, default=40,
                   help="steps of the block per round (default 40)")
    p.add_argument("--block-chunks", type=positive, default=10,
                   help="chunks the block's steps are cut into, run between the scene's steps "
                        "(default 10)")
    p.add_argument("--tiles", choices=["auto", "on", "off"], default="auto",
                   help="the scene's grid node passes over active tiles (on), the whole window "
                        "(off), or as the solver chooses (auto, default)")
