"""The numba cache is emptied when a numba module's source changes (pmpm/jitcache.py): numba
itself checks a cached kernel only against its own file, not the files it inlines from."""
from pmpm import jitcache


def _package(tmp_path, monkeypatch):
    pkg = tmp_path / "pkg"
    (pkg / "kernels" / "__pycache__").mkdir(parents=True)
    (pkg / "shape.py").write_text("import numba\ndef w(s): return s\n")
    (pkg / "cli.py").write_text("print('no kernels here')\n")
    monkeypatch.setattr(jitcache, "_PACKAGE", pkg)
    monkeypatch.setattr(jitcache, "_STAMP", pkg / "__pycache__" / "numba-sources.sha256")
    return pkg


def _cached_kernel(pkg):
    entries = [pkg / "kernels" / "__pycache__" / "transfer.p2g-1.py311.nbi",
               pkg / "kernels" / "__pycache__" / "transfer.p2g-1.py311.1.nbc"]
    for e in entries:
        e.write_bytes(b"machine code")
    return entries


def test_a_changed_inlined_source_empties_the_cache(tmp_path, monkeypatch):
    pkg = _package(tmp_path, monkeypatch)
    assert jitcache.check_cache()  # no stamp yet: emptied and stamped
    entries = _cached_kernel(pkg)
    assert not jitcache.check_cache() and all(e.exists() for e in entries)  # unchanged: kept
    (pkg / "shape.py").write_text("import numba\ndef w(s): return 2 * s\n")
    assert jitcache.check_cache()
    assert not any(e.exists() for e in entries)
    assert not jitcache.check_cache()  # stamped again


def test_a_module_without_numba_does_not_count(tmp_path, monkeypatch):
    pkg = _package(tmp_path, monkeypatch)
    jitcache.check_cache()
    entries = _cached_kernel(pkg)
    (pkg / "cli.py").write_text("print('still no kernels')\n")
    assert not jitcache.check_cache() and all(e.exists() for e in entries)
