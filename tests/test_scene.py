"""Scene loading: every built-in loads, the schema is enforced key by key."""

import numpy as np
import pytest
from helpers import TWO_BODY_SCENE
from steplab.physics.scene import SceneError, builtin_scenes, load_scene, parse_scene


def test_builtins_exist():
    assert {"projectile", "drop", "oscillator", "drag-projectile", "soft-cube", "cloth",
            "n-balls"} <= set(builtin_scenes())


@pytest.mark.parametrize("name", builtin_scenes())
def test_builtin_loads_with_finite_state(name):
    scene = load_scene(name)
    assert scene.y0.shape == (2, scene.model.n_bodies, 3)
    assert np.all(np.isfinite(scene.y0))
    assert scene.t_end > scene.t_start and scene.dt > 0


def test_projectile_is_the_lecture_example():
    scene = load_scene("projectile")
    np.testing.assert_array_equal(scene.y0[:, 0], [[10, 0, 2], [7.68, 0, 29.0]])
    assert float(scene.model.masses[0]) == 2.5 and scene.t_start == 5.0
    np.testing.assert_array_equal(scene.model.constant_acceleration, [[0, 0, -9.81]])


def test_spring_rest_length_defaults_to_initial_distance():
    scene = parse_scene(TWO_BODY_SCENE + '[[forces.springs]]\nbodies = ["a", "b"]\nstiffness = 3.0\n')
    (springs,) = scene.model.forces
    assert float(springs.rest_length[0]) == 1.0
    # at rest length the spring exerts nothing
    np.testing.assert_array_equal(scene.model.acceleration(0, scene.y0[0], scene.y0[1]), 0)


def test_soft_body_grid_and_pinned_vertices():
    scene = parse_scene("""
[simulation]
dt = 0.01
t_end = 1.0
[[soft_bodies]]
name = "c"
shape = "grid"
rows = 3
cols = 4
spacing = 0.5
mass = 1.2
stiffness = 10.0
pinned = [0, 3]
""")
    assert scene.model.n_bodies == 12 and scene.model.names[5] == "c[5]"
    np.testing.assert_allclose(np.asarray(scene.model.masses), 0.1)
    assert list(np.flatnonzero(scene.model.pinned)) == [0, 3]


def test_particles_are_seeded():
    text = TWO_BODY_SCENE + """
[[particles]]
name = "p"
count = 5
seed = 7
mass = 1.0
radius = 0.1
box_min = [0.0, 0.0, 0.0]
box_max = [1.0, 1.0, 1.0]
speed = 3.0
"""
    a, b = parse_scene(text), parse_scene(text)
    np.testing.assert_array_equal(a.y0, b.y0)
    assert np.all(np.linalg.norm(a.y0[1, 2:], axis=1) <= 3.0)


BAD = [
    # (replace this, with this, expected fragment of the message)
    ("mass = 1.0", "mass = -1.0", "bodies[0].mass: must be > 0, got -1"),
    ("mass = 1.0", "mass = 0", "bodies[0].mass: must be > 0"),
    ("radius = 0.1\nposition = [0.0", "radius = 0.0\nposition = [0.0", "bodies[0].radius: must be > 0"),
    ("dt = 0.01", "dt = 0.0", "simulation.dt: must be > 0"),
    ("dt = 0.01", "dt = -0.5", "simulation.dt: must be > 0"),
    ("dt = 0.01", "dt = nan", "simulation.dt: must be finite"),
    ("t_end = 1.0", "t_end = inf", "simulation.t_end: must be finite"),
    ("t_end = 1.0", "t_end = 1.0\nt_start = 2.0", "simulation.t_end: must be later than t_start"),
    ("t_end = 1.0", "", "simulation.t_end: missing required key"),
    ("mass = 1.0", 'mass = "heavy"', "bodies[0].mass: must be a number, got a string"),
    ("position = [0.0, 0.0, 0.0]", "position = [0.0, 0.0]", "bodies[0].position: must be a list of 3 numbers"),
    ("position = [0.0, 0.0, 0.0]", "position = [0.0, nan, 0.0]", "bodies[0].position: must be finite"),
    ('name = "b"', 'name = "a"', "bodies[1].name: duplicate body name 'a'"),
    ('name = "a"', "", "bodies[0].name: missing required key"),
    ("radius = 0.1\nposition = [0.0", "radius = 0.1\ncolour = 3\nposition = [0.0",
     "bodies[0]: unknown key 'colour'"),
    ("[simulation]", "[simulation]\nintegrater = 'rk4'", "simulation: unknown key 'integrater'"),
]


@pytest.mark.parametrize("old,new,message", BAD)
def test_bad_scene_names_the_key(old, new, message):
    text = TWO_BODY_SCENE.replace(old, new, 1)
    assert text != TWO_BODY_SCENE or not old
    with pytest.raises(SceneError, match=None) as err:
        parse_scene(text, "s.toml")
    assert str(err.value).startswith("s.toml: ")
    assert message in str(err.value)
    assert "\n" not in str(err.value)


def test_spring_naming_unknown_body():
    with pytest.raises(SceneError, match=r"forces.springs\[0\].bodies: names unknown body 'c'"):
        parse_scene(TWO_BODY_SCENE + '[[forces.springs]]\nbodies = ["a", "c"]\nstiffness = 1.0\n', "s.toml")


def test_spring_to_itself():
    with pytest.raises(SceneError, match="must name two different bodies"):
        parse_scene(TWO_BODY_SCENE + '[[forces.springs]]\nbodies = ["a", "a"]\nstiffness = 1.0\n')


def test_malformed_toml_names_the_line():
    with pytest.raises(SceneError, match=r"s.toml: malformed TOML: .*line 3"):
        parse_scene("[simulation]\ndt = 0.1\nt_end = = 2\n", "s.toml")


def test_not_utf8():
    with pytest.raises(SceneError, match="not UTF-8"):
        parse_scene(b"[simulation]\n\xff\xfe = 1\n", "s.toml")


def test_no_bodies_and_no_simulation():
    with pytest.raises(SceneError, match="missing required table"):
        parse_scene("[[bodies]]\nname='a'\nmass=1.0\nradius=1.0\nposition=[0,0,0]\n")
    with pytest.raises(SceneError, match="declares no bodies"):
        parse_scene("[simulation]\ndt = 0.1\nt_end = 1.0\n")


def test_unknown_scene_lists_builtins(tmp_path):
    with pytest.raises(SceneError, match="built-in scenes are .*cloth"):
        load_scene("no-such-scene")
    with pytest.raises(SceneError, match="cannot read"):
        load_scene(tmp_path / "missing.toml")


def test_pinned_bodies_never_move():
    with pytest.raises(SceneError, match="bodies\\[0\\].velocity: a pinned body never moves"):
        parse_scene(TWO_BODY_SCENE.replace("position = [0.0, 0.0, 0.0]", "position = [0.0, 0.0, 0.0]\n"
                                    "velocity = [1.0, 0.0, 0.0]\npinned = true", 1))
    from steplab.integrators import simulate

    scene = parse_scene('[simulation]\ndt = 0.01\nt_end = 1.0\n[[soft_bodies]]\nname = "c"\nshape = "box"\n'
                        "mass = 8.0\nstiffness = 100.0\nvelocity = [1.0, 0.0, 0.0]\npinned = [7]\n")
    traj = simulate(scene.model, "semi-implicit-euler", scene.y0, 0, 1, 0.01)
    np.testing.assert_array_equal(traj.positions[:, 7], np.broadcast_to(scene.y0[0, 7], (101, 3)))
