"""Scenes whose every number is finite but which no run or export can represent: one line, status 2.

Found by probing the command line with hostile scenes: each of these ran (or exported) and printed
inf or NaN with status 0, or silently ignored a key.
"""

from __future__ import annotations

import pytest
from helpers import refused
from steplab.physics.scene import SceneError, parse_scene
from steplab.physics.scene_library import SCENES

from steplab.cli import main

POINT = """
[simulation]
dt = 0.01
t_end = 0.1
[[bodies]]
name = "b"
mass = {mass}
radius = 0.1
position = [0, 0, 0]
velocity = [{speed}, 0, 0]
"""


def dzhanibekov(replace: dict) -> str:
    text = SCENES["dzhanibekov"].read_text()
    for old, new in replace.items():
        assert old in text
        text = text.replace(old, new)
    return text


def test_a_start_whose_kinetic_energy_overflows_is_refused(capsys, tmp_path):
    # 1/2 1e300 kg (1e5 m/s)^2 = 5e309 J: past float64, though mass and speed are finite
    path = tmp_path / "k.toml"
    path.write_text(POINT.format(mass=1e300, speed=1e5))
    err = refused(capsys, ["run", str(path)])
    assert "the initial kinetic energy, sum of m |v|^2 / 2, is inf J" in err
    # just inside float64 the same body runs
    path.write_text(POINT.format(mass=1e300, speed=1.0))
    assert main(["run", str(path)]) == 0


@pytest.mark.parametrize("scene,replace,where", [
    ("drag-projectile", {"mass = 0.43": "mass = 1e200", "velocity = [19.8, 0.0, 19.8]": "velocity = [0.0, 0.0, 1e200]"},
     r"bodies\[0\]\.velocity: the initial kinetic energy, .* is inf J, beyond float64 \(the term of body 'ball' alone "
     r"is\)"),
    ("dzhanibekov", {"angular_velocity = [0.05, 6.283185307179586, 0.05]": "angular_velocity = [1e200, 0, 0]"},
     r"bodies\[0\]\.angular_velocity: the initial rotational kinetic energy, .* \(the term of body 'box' alone is\)"),
    ("drag-projectile", {"position = [0.0, 0.0, 0.0]": "position = [0.0, 0.0, 1.7e308]"},
     r"s\.toml: the initial potential energy of the forces is inf J, beyond float64 \(forces\.gravity's alone is\)"),
    ("kepler", {"mu = 39.47841760435743": "mu = 1.7e308"}, r"\(forces\.central_gravity's alone is\)"),
])
def test_an_energy_that_overflows_names_its_body_or_force(scene, replace, where):
    # the input audit: the refusal named the file only ("masses, speeds, spins or forces too large")
    text = SCENES[scene].read_text()
    for old, new in replace.items():
        assert old in text
        text = text.replace(old, new)
    with pytest.raises(SceneError, match=where):
        parse_scene(text, "s.toml")


def test_a_spin_whose_energy_overflows_is_refused():
    with pytest.raises(SceneError, match=r"the initial rotational kinetic energy, .* is inf J"):
        parse_scene(dzhanibekov({"angular_velocity = [0.05, 6.283185307179586, 0.05]":
                                 "angular_velocity = [1e200, 0, 0]"}))
    assert parse_scene(dzhanibekov({"angular_velocity = [0.05, 6.283185307179586, 0.05]":
                                    "angular_velocity = [1e150, 0, 0]"})).rigid_bodies.kinetic_energy() < 1e300


@pytest.mark.parametrize("shape,key,value", [
    ("mesh", "center", "[9, 9, 9]"),       # a box's key: the mesh would not move
    ("box", "vertices", "[[0, 0, 0], [1, 0, 0]]"),
    ("box", "rows", "3"),
    ("grid", "size", "[1, 1, 1]"),
])
def test_a_soft_body_key_of_another_shape_is_refused(shape, key, value):
    described = {"box": "", "grid": "rows = 2\ncols = 2\nspacing = 0.1\n",
                 "mesh": "vertices = [[0, 0, 0], [1, 0, 0]]\n"}[shape]
    text = (f'[simulation]\ndt = 0.01\nt_end = 0.1\n[[soft_bodies]]\nname = "s"\nshape = "{shape}"\n'
            f"{described}mass = 1.0\nstiffness = 10.0\n")
    assert parse_scene(text).model.n_bodies > 0  # the shape's own keys are fine
    with pytest.raises(SceneError, match=rf'soft_bodies\[0\]\.{key}: belongs to a soft body of shape "\w+"; '
                                         rf'this one\'s shape is "{shape}"'):
        parse_scene(text + f"{key} = {value}\n")


@pytest.mark.parametrize("name", ['""', '"a\\nb"', '"tab\\there"'])
def test_a_body_name_must_print_on_one_line(name):
    with pytest.raises(SceneError, match="bodies\\[0\\].name: must be a non-empty name of printable characters"):
        parse_scene(POINT.format(mass=1.0, speed=0.0).replace('"b"', name))
    assert parse_scene(POINT.format(mass=1.0, speed=0.0).replace('"b"', '"球 ball-2"')).model.names == ("球 ball-2",)


def test_an_inextensible_spring_is_not_exported_to_mujoco(capsys, tmp_path):
    path = tmp_path / "c.toml"
    path.write_text(SCENES["cloth"].read_text().replace("stiffness = 100.0", "stiffness = inf"))
    err = refused(capsys, ["export", str(path), "--to", "mjcf"])
    assert "the inextensible spring (stiffness = inf)" in err and "MuJoCo gets springs of finite stiffness" in err


def test_a_box_whose_moments_give_no_finite_edges_is_not_exported(capsys, tmp_path):
    # without collisions the engines take a box's edges from its moments: 1e307 kg m^2 on 0.2 kg overflows
    path = tmp_path / "d.toml"
    path.write_text(dzhanibekov({"size = [0.3, 0.2, 0.1]": "size = [0.3, 0.2, 0.1]\ninertia = [1e307, 1e307, 1e307]",
                                 "angular_velocity = [0.05, 6.283185307179586, 0.05]": "angular_velocity = [0, 0, 0]"}))
    err = refused(capsys, ["export", str(path), "--to", "mjcf"])
    assert "has edges beyond float64" in err


def test_a_spring_with_no_finite_compliance_is_refused_by_the_position_based_methods(capsys, tmp_path):
    # k = 1e-320 N/m is a spring of no force for the force-based methods; pbd and xpbd need alpha = 1 / k
    path = tmp_path / "c.toml"
    path.write_text(SCENES["cloth"].read_text().replace("stiffness = 100.0", "stiffness = 1e-320"))
    for method in ("pbd", "xpbd"):
        err = refused(capsys, ["run", str(path), "--integrator", method, "--t-end", "0.01"])
        assert "a spring of stiffness 1e-320 N/m has no finite compliance 1 / k" in err
    assert main(["run", str(path), "--integrator", "semi-implicit-euler", "--t-end", "0.01"]) == 0


def test_a_subnormal_moment_of_inertia_is_refused():
    # 1 / 1e-310 overflows: dlm's first step was "diverged at step 1", the contact solver's "non-finite"
    spun = {"angular_velocity = [0.05, 6.283185307179586, 0.05]": "inertia = [1e-310, 1e-310, 1e-310]"}
    with pytest.raises(SceneError, match=r"bodies\[0\]\.inertia: inertia must be at least 5\.56e-309 kg m\^2 in "
                                         r"every moment \(a smaller one has no finite inverse\), got "
                                         r"\[1e-310, 1e-310, 1e-310\]"):
        parse_scene(dzhanibekov(spun))
    smallest = {"angular_velocity = [0.05, 6.283185307179586, 0.05]": "inertia = [6e-309, 6e-309, 6e-309]"}
    assert parse_scene(dzhanibekov(smallest)).rigid_bodies.inertia[0, 0] == 6e-309


def test_a_box_near_the_float_range_exports_its_centre(capsys, tmp_path):
    # lo + hi of the box overflowed: the MJCF said pos="0.0 0.0 -inf"
    path = tmp_path / "b.toml"
    path.write_text('[simulation]\ndt = 0.01\nt_end = 0.1\n[[bodies]]\nname = "b"\nmass = 1.0\nradius = 0.1\n'
                    'position = [0, 0, 5]\n[collisions]\n[[collisions.boxes]]\nname = "wall"\n'
                    'center = [0.0, 0.0, -1e308]\nsize = [1e308, 1e308, 1e308]\n')
    assert main(["export", str(path), "--to", "mjcf"]) == 0
    out = capsys.readouterr().out
    assert 'pos="0.0 0.0 -1e+308" size="5e+307 5e+307 5e+307"' in out and "inf" not in out


@pytest.mark.parametrize("old,new,key,size", [("radius = 0.05", "radius = 1e151", "radius", r"1e\+151"),
                                              ("position = [-2.0,", "position = [-2e151,", "position", r"2e\+151")])
def test_a_body_beyond_the_broadphase_range_is_refused_in_a_collision_scene(old, new, key, size):
    # squared distances overflow past 1e150 m: the run "diverged at step 1", or the broadphase refused mid-run
    # naming no file or key
    from importlib import resources

    text = (resources.files("steplab.physics") / "scenes" / "tunnelling.toml").read_text()
    assert old in text
    with pytest.raises(SceneError, match=rf"^s\.toml: bodies\[0\]\.{key}: body 'bullet': a {key} of {size} m in a "
                                         r"scene with \[collisions\]; at most 1e\+150 m"):
        parse_scene(text.replace(old, new), "s.toml")
    parse_scene(text.replace(old, new), "s.toml", collisions=False)  # without collisions nothing squares them
