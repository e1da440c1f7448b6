"""The first render of a process says it may be compiling kernels (so it never looks frozen)."""
from __future__ import annotations

import stpm_core.render as render_mod
from stpm_core.demo import demo_scene
from stpm_core.settings import RenderSettings


def test_first_render_of_a_process_announces_kernel_loading(monkeypatch):
    monkeypatch.setattr(render_mod, "_FIRST_RENDER", True)
    st = RenderSettings(samples=1, photons_caustic=0, photons_global=0, seed=1)
    messages = []
    render_mod.render(demo_scene((16, 12)), st, progress=lambda f, m: messages.append(m))
    assert "compiled kernels" in messages[0]
    messages.clear()
    render_mod.render(demo_scene((16, 12)), st, progress=lambda f, m: messages.append(m))
    assert not any("compiled kernels" in m for m in messages)      # only once per process
