"""Every numba compilation (a disk-cache miss) is announced, per kernel family, and a
kernel loaded from the cache is not: the decision is per kernel, not 'any cache file'."""

from __future__ import annotations

import importlib
import sys
import textwrap

import pytest

numba = pytest.importorskip("numba")

from animsim.compile_notice import compile_notices  # noqa: E402


def _module(tmp_path, name: str):
    (tmp_path / f"{name}.py").write_text(
        textwrap.dedent(
            """
            import numba

            @numba.njit(cache=True)
            def twice(x):
                return 2.0 * x
            """
        )
    )
    sys.path.insert(0, str(tmp_path))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(str(tmp_path))


def test_a_compilation_is_announced_and_a_cache_hit_is_not(tmp_path):
    heard: list[str] = []
    mod = _module(tmp_path, "fm_cached_kernel")
    with compile_notices(heard.append):
        assert mod.twice(2.0) == 4.0
    assert heard[0] == "compiling numba kernels: fm_cached_kernel (twice), once; cached afterwards..."
    assert heard[-1].startswith("compiled 1 numba kernel(s) in ")
    assert "(fm_cached_kernel " in heard[-1] and heard[-1].endswith("; the next runs load them")
    # a new dispatcher of the same function loads it from the disk cache: nothing to say
    heard.clear()
    sys.modules.pop("fm_cached_kernel")
    mod = _module(tmp_path, "fm_cached_kernel")
    with compile_notices(heard.append):
        assert mod.twice(3.0) == 6.0
    assert heard == []


def test_nested_blocks_give_one_summary():
    heard: list[str] = []
    with compile_notices(heard.append), compile_notices(heard.append):
        numba.njit(lambda x: x + 1)(1)  # no file: never cached, always compiled
    assert len([h for h in heard if h.startswith("compiled ")]) == 1


def test_without_a_notice_nothing_is_heard():
    with compile_notices(None) as session:
        numba.njit(lambda x: x + 2)(1)
    assert session is None


@pytest.mark.slow
def test_a_run_with_an_empty_cache_announces_its_kernels(tmp_path, monkeypatch):
    """Element kernels made by jit_kernel look in numba's cache folder when they are made:
    an empty one means every element kernel of the scene compiles, and the run says so."""
    from animsim import elements
    from animsim.compile import compile_scene
    from animsim.engine import run
    from animsim.scene.loader import load_scene
    from tests.conftest import SCENES

    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(elements, "_JITTED", {})
    heard: list[str] = []
    compiled = compile_scene(load_scene(SCENES / "spring_pendulum.yaml").scene, "p", backend="numba")
    result = run(compiled, [], notice=heard.append)
    assert result.status == "ok"
    families = {h.split(": ")[1].split(" (")[0] for h in heard if h.startswith("compiling ")}
    assert {"gravity", "springs"} <= families, heard
    assert heard[-1].startswith("compiled ") and len([h for h in heard if h.startswith("compiled ")]) == 1


def test_the_estimate_quotes_the_measured_times():
    """The notice's figure is the table's (median, longest), rounded, never made up."""
    from animsim import compile_notice

    table = {"a": (4.3, 82.4), "b": (19.2, 25.0), "c": (0.4, 0.9), "d": (0.6, 1.8)}
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(compile_notice, "SECONDS", table)
        mp.setattr(compile_notice, "MACHINE", "a 2-core test machine")
        assert compile_notice.how_long("a") == "about 4 s, at most 82 s, on a 2-core test machine"
        assert compile_notice.how_long("b") == "about 19 s on a 2-core test machine"
        assert compile_notice.how_long("c") == "under 1 s on a 2-core test machine"
        assert compile_notice.how_long("d") == "under 1 s, at most 2 s, on a 2-core test machine"
        assert compile_notice.how_long("never measured") == ""
