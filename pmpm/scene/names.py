"""Names from a scene that become file names, and the files a run writes.

The rule (docs/scenes.md, "File names"): a name that becomes part of a file name (the scene
file's stem, a variant name, a track name) is 1 to 64 characters from ``A-Z a-z 0-9 _ - .``,
starts with a letter or a digit, holds no ``..``, and is not a name Windows reserves
(``CON``, ``PRN``, ``AUX``, ``NUL``, ``COM1``-``COM9``, ``LPT1``-``LPT9``, in any case and with
any extension). Track names are also not ``time`` (a dataset of the history group). Names are
checked, never rewritten, so the file a name gives is always the one the user expects.

Every file a run writes is listed by :func:`run_files`; :func:`check_output_files` refuses two
names that give the same file (compared ignoring case, as on macOS and Windows file systems)
and any file that would not lie inside ``output.directory``.
"""
import os
import re

from pmpm.errors import ConfigError

__all__ = ["check_name", "run_files", "check_output_files", "check_output_directory",
           "output_base", "run_name", "track_csv", "history_png", "energies_png", "deformed_png",
           "NAME_PATTERN"]

NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")
_RESERVED = {"con", "prn", "aux", "nul", *(f"com{i}" for i in range(1, 10)),
             *(f"lpt{i}" for i in range(1, 10))}


def check_name(name, key, what="name", also_reserved=()):
    """Refuse ``name`` unless it follows the file-name rule.

    Parameters
    ----------
    name : str
        The name (scene stem, variant, track).
    key : str
        Dotted key (or file) the error names.
    what : str
        What the name is, for the reason.
    also_reserved : tuple of str
        Further names refused (lower case), e.g. ``("time",)`` for tracks.

    Returns
    -------
    str
        ``name``, unchanged.
    """
    if not isinstance(name, str) or not name:
        raise ConfigError(key, f"{what} must not be empty")
    if not NAME_PATTERN.fullmatch(name):
        raise ConfigError(key, f"{what} {name!r} may hold only letters, digits, '_', '-' and '.' "
                               f"(1 to 64, starting with a letter or digit)" if len(name) <= 64 else
                          f"{what} longer than 64 characters")
    if ".." in name:
        raise ConfigError(key, f"{what} {name!r} must not contain '..'")
    if name.split(".")[0].lower() in _RESERVED or name.lower() in also_reserved:
        raise ConfigError(key, f"{what} {name!r} is a reserved name")
    return name


def run_name(scene):
    """``<stem>[_<variant>]``: the name of one run, the prefix of every file it owns alone."""
    return scene.stem + (f"_{scene.variant}" if scene.variant else "")


def output_base(scene):
    """``<output.directory>/<stem>[_<variant>]``: the common prefix of the run's HDF5 files."""
    return os.path.join(scene.output.directory, run_name(scene))


# The files written after the run (pmpm.io.post, pmpm plot). Every name starts with the scene's
# stem, so scenes sharing an output folder never share a file; the history plot overlays every
# variant of the scene and so carries the stem alone.
def track_csv(run, track):
    """``<run>_history_<track>.csv``: the time history of one tracked point."""
    return f"{run}_history_{track}.csv"


def history_png(stem, track):
    """``<stem>_history_<track>.png``: one tracked point, every variant overlaid."""
    return f"{stem}_history_{track}.png"


def energies_png(run):
    """``<run>_energies.png``: the energies and the balance error of one run."""
    return f"{run}_energies.png"


def deformed_png(run):
    """``<run>_deformed.png``: the deformed shape at the largest tracked displacement."""
    return f"{run}_deformed.png"


def run_files(scene):
    """(key that made it, file name) of every file the run of ``scene`` may write, relative
    to ``output.directory``."""
    run = run_name(scene)
    key = f"variants.{scene.variant}" if scene.variant else "scene file name"
    files = [(key, run + ext) for ext in (".h5", ".xdmf", ".ckpt0.h5", ".ckpt1.h5", ".lastgood.h5")]
    for k, tr in enumerate(scene.output.track):
        files.append((f"output.track[{k}].name", track_csv(run, tr.name)))
        # the history plot overlays every variant: one shared file (see check_output_files)
        files.append((f"output.track[{k}].name", history_png(scene.stem, tr.name)))
    files.append((key, energies_png(run)))
    # structural results (pmpm.results.post): per section and recorded reaction, and plots
    for k, sec in enumerate(getattr(scene.output, "sections", ())):
        files.append((f"output.section[{k}].name", f"{run}_section_{sec.name}.csv"))
    for k, b in enumerate(scene.boundaries):
        if getattr(b, "reaction", False):
            files.append((f"boundary[{k}].name", f"{run}_reaction_{b.name}.csv"))
    for plot in ("sections", "utilisation", "hinges", "reactions", "hysteresis"):
        files.append((key, f"{run}_{plot}.png"))
    if scene.output.deformed_plot:
        files.append(("output.deformed_plot", deformed_png(run)))
    if getattr(scene, "pushover", None) is not None:  # its capacity curve (pmpm.results.capacity)
        files += [("pushover", f"{run}_capacity.csv"), ("pushover", f"{run}_capacity.png")]
    return files


def check_output_files(scenes):
    """Refuse two names giving the same file and files outside ``output.directory``.

    Parameters
    ----------
    scenes : list of Scene
        Every run of one scene file (its variants).

    Raises
    ------
    ConfigError
        Naming the key of the second name that gives a file, or that leaves the directory.
    """
    seen = {}
    for scene in scenes:
        directory = os.path.realpath(scene.output.directory)
        for key, name in run_files(scene):
            path = os.path.realpath(os.path.join(scene.output.directory, name))
            if os.path.dirname(path) != directory:  # a separator or '..' got through
                raise ConfigError(key, f"gives a file outside output.directory ({name!r})")
            where = (directory, name.lower())
            if where in seen:
                label, first_key, first_name = seen[where]
                shared = name.startswith(f"{scene.stem}_history_") and name.endswith(".png")
                if shared and first_key == key and first_name == name:
                    continue  # the same track of every variant shares its overlaid plot
                raise ConfigError(key, f"gives the file {name!r}, as {label} does "
                                       f"(file names are compared ignoring case)")
            seen[where] = (key + (f" of variant {scene.variant!r}" if scene.variant else ""), key, name)


#: kernel file systems: writes there fail or do something else than store a file
_PSEUDO = ("/proc", "/sys", "/dev")


def check_output_directory(directory, key="output.directory"):
    """Refuse an output directory that is empty, a file, below a file or not writable (no
    file is created here)."""
    if not isinstance(directory, str) or not directory.strip():
        raise ConfigError(key, "must not be empty")
    if "\0" in directory:
        raise ConfigError(key, "holds a NUL character")
    path = os.path.abspath(directory)
    real = os.path.realpath(path)
    for system in _PSEUDO:
        if real == system or real.startswith(system + os.sep):
            raise ConfigError(key, f"{directory!r} lies in {system}, a kernel file system, not a "
                                   f"place for results")
    if os.path.exists(path) and not os.path.isdir(path):
        raise ConfigError(key, f"{directory!r} exists and is not a directory")
    probe = path
    while not os.path.exists(probe):
        parent = os.path.dirname(probe)
        if parent == probe:
            break
        probe = parent
    if not os.path.isdir(probe):
        raise ConfigError(key, f"{directory!r} lies below a file ({probe!r} is not a directory)")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise ConfigError(key, f"{directory!r} is not writable ({probe!r} denies it)")
