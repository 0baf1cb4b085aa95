"""pmpm's numba cache lives in a directory named by the hash of its numba modules' sources
(pmpm/jitcache.py): numba itself checks a cached kernel only against its own file, not the
files it inlines from, so a changed shape.py must never meet kernels compiled from the old one."""
import os
import time

import numba
import pytest

from pmpm import jitcache


@pytest.fixture
def package(tmp_path, monkeypatch):
    pkg = tmp_path / "pkg"
    (pkg / "kernels").mkdir(parents=True)
    (pkg / "shape.py").write_text("import numba\ndef w(s): return s\n")
    (pkg / "kernels" / "transfer.py").write_text("from numba import njit\n")
    (pkg / "cli.py").write_text("print('no kernels here, though numba is named')\n")
    monkeypatch.setattr(jitcache, "_PACKAGE", pkg)
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setattr(numba.config, "CACHE_DIR", numba.config.CACHE_DIR)
    return pkg


def test_changed_kernel_sources_get_a_new_directory(package):
    first = jitcache.use_versioned_cache()
    assert first.startswith(str(package / "__pycache__" / "numba-"))
    assert os.environ["NUMBA_CACHE_DIR"] == first == numba.config.CACHE_DIR  # ranks inherit it
    assert jitcache.use_versioned_cache() == first  # unchanged sources, same place
    (package / "cli.py").write_text("print('still no kernels')\n")
    assert jitcache.use_versioned_cache() == first  # a module without numba does not count
    (package / "shape.py").write_text("import numba\ndef w(s): return 2 * s\n")
    second = jitcache.use_versioned_cache()
    assert second != first and os.path.dirname(second) == os.path.dirname(first)


def test_a_users_cache_dir_is_the_parent_and_old_versions_go_after_a_day(package, tmp_path, monkeypatch):
    user = tmp_path / "user-cache"
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(user))
    target = jitcache.use_versioned_cache()
    assert os.path.dirname(target) == str(user)
    stale, recent = user / "numba-0000000000000000", user / "numba-1111111111111111"
    for d in (stale, recent):
        (d / "sub").mkdir(parents=True)
    day_old = time.time() - 2 * jitcache._KEEP_OLD
    os.utime(stale, (day_old, day_old))
    assert jitcache.use_versioned_cache() == target  # the variable now names the version dir
    assert not stale.exists() and recent.exists()  # recent: a running process may still write
