"""The user's cache: where it is, entries that survive a process, and broken entries built again."""

from __future__ import annotations

import numpy as np

from swarmpose.core import cache


def test_the_folder_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("SWARMPOSE_CACHE_DIR", str(tmp_path / "mine"))
    assert cache.cache_dir() == tmp_path / "mine"
    monkeypatch.delenv("SWARMPOSE_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache.cache_dir() == tmp_path / "xdg" / "swarmpose"


def test_an_entry_is_built_once_read_back_and_built_again_when_broken(monkeypatch, tmp_path):
    monkeypatch.setenv("SWARMPOSE_CACHE_DIR", str(tmp_path))
    calls = []

    def build():
        calls.append(1)
        return {"a": np.arange(6.0).reshape(2, 3), "b": np.array([1, 2], np.int32)}

    key = cache.cache_key("x", 1)
    first = cache.cached_arrays("kind", key, build)
    second = cache.cached_arrays("kind", key, build)
    assert len(calls) == 1
    for name in ("a", "b"):
        np.testing.assert_array_equal(first[name], second[name])
        assert first[name].dtype == second[name].dtype
    (tmp_path / "kind" / f"{key}.npz").write_bytes(b"not a zip")
    cache.cached_arrays("kind", key, build)
    assert len(calls) == 2
    assert cache.cache_key("x", 1) != cache.cache_key("x", 2)


def test_an_unwritable_cache_still_gives_the_value(monkeypatch, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("SWARMPOSE_CACHE_DIR", str(blocker))
    assert cache.cached_arrays("kind", "k", lambda: {"a": np.ones(2)})["a"].tolist() == [1.0, 1.0]


def test_the_builtin_body_from_the_cache_is_the_body_meshed_anew(monkeypatch, tmp_path):
    from swarmpose.body import parametric

    monkeypatch.setenv("SWARMPOSE_CACHE_DIR", str(tmp_path))
    parametric.build_parametric_body.cache_clear()
    try:
        stored = parametric.build_parametric_body()
        assert list((tmp_path / "bodies").glob("*.npz"))
        parametric.build_parametric_body.cache_clear()
        again = parametric.build_parametric_body()
    finally:
        parametric.build_parametric_body.cache_clear()
    fresh = parametric._mesh_arrays(parametric.BodyShape(), 0.01)
    assert set(fresh) == set(parametric._ARRAYS)
    for name in parametric._ARRAYS:
        np.testing.assert_array_equal(getattr(again, name), fresh[name])
        np.testing.assert_array_equal(getattr(stored, name), fresh[name])
    assert again.name == stored.name == "builtin" and again.bone_names == parametric.BONE_NAMES
