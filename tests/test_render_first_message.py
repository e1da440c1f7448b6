"""The first render of a process says whether the kernels load or compile (so it never looks frozen),
and every render reports how many kernels numba compiled (``kernels_compiled``)."""
from __future__ import annotations

import stpm_core.kernels as kernels
import stpm_core.render as render_mod
from stpm_core.demo import demo_scene
from stpm_core.settings import RenderSettings

ST = RenderSettings(samples=1, photons_caustic=0, photons_global=0, seed=1)


def test_first_render_of_a_process_announces_kernel_loading(monkeypatch):
    monkeypatch.setattr(kernels, "_FIRST_RENDER", [True])
    monkeypatch.setattr(kernels, "kernels_cached", lambda: True)
    messages = []
    res = render_mod.render(demo_scene((16, 12)), ST, progress=lambda f, m: messages.append(m))
    assert messages[0] == "loading compiled kernels"
    assert not any("compiling" in m for m in messages)
    assert res.stats["kernels_compiled"] >= 0 and "kernel_cache_source" in res.stats
    messages.clear()
    res = render_mod.render(demo_scene((16, 12)), ST, progress=lambda f, m: messages.append(m))
    assert not any("compiled kernels" in m for m in messages)      # only once per process
    assert res.stats["kernels_compiled"] == 0                      # everything compiled or loaded already


def test_a_cold_cache_says_compiling_in_every_message_of_the_first_render(monkeypatch):
    monkeypatch.setattr(kernels, "_FIRST_RENDER", [True])
    monkeypatch.setattr(kernels, "kernels_cached", lambda: False)
    messages = []
    render_mod.render(demo_scene((16, 12)), ST, progress=lambda f, m: messages.append(m))
    assert messages[0].startswith("compiling kernels: the first render after installing")
    assert all(m.endswith("(compiling kernels on first use)") for m in messages[1:] if m)
    assert len(messages) > 2


def test_the_kernels_in_memory_count_as_cached():
    render_mod.render(demo_scene((16, 12)), ST)
    assert kernels.kernels_cached() is True
