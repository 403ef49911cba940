"""The engines on stacks of boxes (steplab.engines.stacks): the measures against made-up motions
with known answers, boxes resting at the height their edges give, and one-line refusals.

The engine tests need the engines extra (pip install -e ".[engines]") and are skipped per engine
without it. The scenes are small hand-written ones: boxes as [[bodies]] on a floor plane.
"""

import numpy as np
import pytest
from steplab.physics.scene import parse_scene

from steplab.engines import ENGINES, UnsupportedFeatureError
from steplab.engines.stacks import SETTLE, STANDING_TOLERANCE, run_stack, stack_measures, stack_setting

#: a box that is not a cube, so that a mix-up of its edges changes the height it rests at
SIZE = (0.4, 0.3, 0.2)


def scene_text(boxes, dt=1 / 60, t_end=2.0) -> str:
    """A floor plane (friction 0.6, no bounce) and ``boxes``: (name, z of the centre, mass)."""
    text = f"""[simulation]
integrator = "semi-implicit-euler"
dt = {dt!r}
t_end = {t_end!r}

[forces.gravity]

[collisions]
detector = "overlap"
restitution = 0.0
friction = 0.6

[[collisions.planes]]
name = "floor"
normal = [0.0, 0.0, 1.0]
offset = 0.0
"""
    for name, z, mass in boxes:
        text += f"""
[[bodies]]
name = "{name}"
mass = {mass!r}
radius = 0.1
position = [0.0, 0.0, {z!r}]
shape = "box"
size = [{SIZE[0]!r}, {SIZE[1]!r}, {SIZE[2]!r}]
"""
    return text


def needs(engine: str):
    return pytest.importorskip(ENGINES[engine].package, reason=f"{engine} is not installed")


def test_the_measures_of_a_made_up_drift():
    """The top box creeps at 0.9 mm/s after a 5 cm sink and the box below is still: the drift over the
    9 s after SETTLE is 8.1 mm (standing), the rms speed is that of one box in two, and the top box
    stands from the first saved time at or after its sink."""
    t = np.arange(0.0, 10.0 + 1e-9, 0.1)
    q = np.zeros((len(t), 2, 3))
    q[:, 0, 2], q[:, 1, 2] = 0.1, 0.3
    q[t >= SETTLE, 1, 2] -= 0.05
    speed = 9e-4
    q[:, 1, 0] = np.where(t >= SETTLE, speed * (t - SETTLE), 0.0)
    v = np.zeros_like(q)
    v[t >= SETTLE, 1, 0] = speed
    found = stack_measures(t, q, v, np.array([0.0, 0.0, 1.0]))
    assert found["top"] == 1 and found["standing"]
    assert found["top_drift"] == pytest.approx(speed * 9.0, rel=1e-12) == found["drift"]
    assert found["jitter"] == pytest.approx(speed / np.sqrt(2), rel=1e-12)
    assert found["deflection"] == pytest.approx(0.05, rel=1e-12)
    assert found["at_rest_after"] == pytest.approx(SETTLE)
    q[-1, 1, 0] += STANDING_TOLERANCE  # a last jump of 1 cm: fallen, and it comes to rest only then
    found = stack_measures(t, q, v, np.array([0.0, 0.0, 1.0]))
    assert not found["standing"] and found["at_rest_after"] is None


@pytest.mark.parametrize("engine", [key for key, cls in ENGINES.items() if cls.contacts])  # Newton: no contacts
def test_a_box_rests_at_half_its_height_and_a_pair_stands(engine):
    """Two boxes 0.2 m tall, stacked: each engine's default setting keeps them standing, and the
    lower one rests at 0.1 m (within the engine's contact slop or skin and soft deflection, 1.5 cm),
    the upper at 0.3 m: the engine's box has the scene's edges, in the body's axes."""
    needs(engine)
    scene = parse_scene(scene_text([("low", 0.1, 1.0), ("high", 0.3, 1.0)]))
    found = run_stack(engine, scene)
    assert found["standing"] and found["top"] == 1 and found["diverged_at"] is None, found
    assert found["jitter"] < 0.01 and found["seconds_per_step"] > 0
    assert abs(found["deflection"]) < 0.015  # the sink at SETTLE: about 0.2 m would be a box turned on its side
    assert found["boxes"] == 2 and found["steps"] == 120 and found["setting"] == ENGINES[engine].stack_settings[0].key


def test_stack_settings_are_declared_and_refused_in_one_line():
    for cls in (cls for cls in ENGINES.values() if cls.contacts):  # an engine without contacts stacks nothing
        assert len(cls.stack_settings) >= 2, cls.engine  # its defaults and a tuned setting
        assert all(s.deviation for s in cls.stack_settings)
    assert stack_setting("mujoco", "mujoco-pgs").options == {"solver": "PGS"}
    assert stack_setting("bullet", {"substeps": 2}).options == {"substeps": 2}
    with pytest.raises(ValueError, match="unknown stack setting 'fast' of box2d; valid: box2d-default, "):
        stack_setting("box2d", "fast")


def test_a_stack_needs_time_after_settling():
    scene = parse_scene(scene_text([("low", 0.1, 1.0)]))
    with pytest.raises(ValueError, match="t_end must exceed the settling time 1 s"):
        run_stack("mujoco", scene, t_end=0.5)


@pytest.mark.parametrize("engine", ["box2d", "chipmunk"])
def test_a_planar_engine_refuses_a_stack_out_of_one_plane(engine):
    needs(engine)
    text = scene_text([("low", 0.1, 1.0)]) + """
[[bodies]]
name = "beside"
mass = 1.0
radius = 0.1
position = [1.0, 1.0, 0.5]
shape = "box"
size = [0.4, 0.3, 0.2]
"""
    with pytest.raises(UnsupportedFeatureError) as err:
        run_stack(engine, parse_scene(text))
    assert "\n" not in str(err.value) and "plane" in str(err.value)
