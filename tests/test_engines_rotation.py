"""The engines on rotating bodies: each adapter's frames against independent conversions, each
engine setting named as the steplab rotation method it declares, and a spin in a plane against
the exact rotation.

Each test needs its engine (the extra pip install -e ".[engines]") and is skipped without it.
"""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from steplab.physics import Gravity, Model
from steplab.physics import quaternion as quat
from steplab.physics.rigid_body import RigidBodies, principal_inertia
from steplab.studies import rotation_engines

from steplab.engines import ENGINES, ROTATION_SETTINGS, UnsupportedFeatureError, build

#: a general orientation and world angular velocity of the flip box (0.2 kg, 0.3 x 0.2 x 0.1 m)
MASS, SIZE = 0.2, [0.3, 0.2, 0.1]
AXIS = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
OMEGA = np.array([0.4, 6.0, -1.1])


def needs(engine: str):
    """The engine's package, imported; a skip where it is not installed."""
    return pytest.importorskip(ENGINES[engine].package, reason=f"{engine} is not installed")


def tilted_box(omega=OMEGA, q=None) -> tuple[Model, RigidBodies]:
    q = quat.from_axis_angle(np, AXIS, 0.7) if q is None else q
    inertia = principal_inertia("box", MASS, 0.05, SIZE)
    return Model([MASS], [0.05], []), RigidBodies(np.array([0]), inertia[None], np.array([q]),
                                                  np.array([omega], float), ("box",))


def scipy_rotation(q) -> Rotation:
    return Rotation.from_quat(np.asarray(q)[[1, 2, 3, 0]])  # scipy's order is (x, y, z, w)


def test_mujoco_free_joint_angular_velocity_is_the_body_frames():
    """qvel's angular part is R^T omega_world (scipy's rotation), and MuJoCo's own world-frame body
    velocity (mj_objectVelocity) is omega_world; the adapter reads omega_world back."""
    mujoco = needs("mujoco")
    model, bodies = tilted_box()
    run = build("mujoco", model, None, 0.01, np.zeros((2, 1, 3)), bodies=bodies)
    run.set_state(np.zeros((2, 1, 3)))
    run.set_rotation(bodies.orientations, bodies.angular_velocities)
    rotation = scipy_rotation(bodies.orientations[0])
    np.testing.assert_allclose(run.data.qpos[3:], bodies.orientations[0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(run.data.qvel[3:], rotation.inv().apply(OMEGA), rtol=0, atol=1e-13)
    mujoco.mj_forward(run.model, run.data)
    velocity = np.zeros(6)
    mujoco.mj_objectVelocity(run.model, run.data, mujoco.mjtObj.mjOBJ_BODY, 1, velocity, 0)
    np.testing.assert_allclose(velocity[:3], OMEGA, rtol=0, atol=1e-13)
    q, omega = run.rotation()
    np.testing.assert_allclose(omega[0], OMEGA, rtol=0, atol=1e-13)
    np.testing.assert_allclose(run.model.body_inertia[1], bodies.inertia[0], rtol=1e-15)


def test_pybullet_orientation_and_angular_velocity_are_converted():
    """pybullet's (x, y, z, w) and world-frame omega; its inertia is the body's (and its mass kept)."""
    needs("bullet")
    model, bodies = tilted_box()
    run = build("bullet", model, None, 0.01, np.zeros((2, 1, 3)), bodies=bodies)
    run.set_state(np.zeros((2, 1, 3)))
    run.set_rotation(bodies.orientations, bodies.angular_velocities)
    pb, body = run._pb, run.bodies[0]
    orientation = pb.getBasePositionAndOrientation(body, **run._p)[1]
    np.testing.assert_allclose(scipy_rotation(bodies.orientations[0]).as_quat(), orientation, atol=1e-15)
    np.testing.assert_allclose(pb.getBaseVelocity(body, **run._p)[1], OMEGA, atol=1e-15)
    mass, _, inertia = pb.getDynamicsInfo(body, -1, **run._p)[:3]
    assert mass == MASS and np.allclose(inertia, bodies.inertia[0], rtol=1e-15)
    run.close()


@pytest.fixture(scope="module")
def references():
    return rotation_engines.reference_runs(rotation_engines.parameters(True))


@pytest.mark.parametrize("key", list(ROTATION_SETTINGS))
def test_identification_names_the_rotation_method_each_setting_declares(key, references):
    """On the tilted tumble (3-D engines) and the spin in a plane, the setting equals the steplab
    rotation method it declares to its precision's round-off, or none where it declares none."""
    setting = ROTATION_SETTINGS[key]
    needs(setting.engine)
    found = rotation_engines.identify(setting, rotation_engines.parameters(True), references)
    if setting.equals is None:
        assert found["equals"] == [] and found["difference"] > 100 * found["tolerance"], found
    else:
        assert setting.equals in found["equals"], found
        assert found["difference"] <= found["tolerance"]
    assert ("tumble" in found["unsupported"]) == setting.adapter.planar
    assert found["equals"] != list(ROTATION_SETTINGS) and "explicit" not in found["equals"]


def test_an_engine_that_diverges_is_judged_on_the_problems_it_ran(references, monkeypatch):
    # a divergence made every method's worst difference inf, and the nearest whichever came first
    from steplab.integrators import DivergenceError

    labels = iter(rotation_engines.problems())  # identify runs them in this order

    def engine_run(setting, model, bodies, dt, n):
        label = next(labels)
        if label == "tumble":
            raise DivergenceError("fake", dt, 1, dt)
        return references[label]["exponential-map"]

    monkeypatch.setattr(rotation_engines, "engine_run", engine_run)
    setting = ROTATION_SETTINGS["mujoco-euler"]
    found = rotation_engines.identify(setting, rotation_engines.parameters(True), references)
    assert found["diverged"] == ["tumble"] and found["equals"] == [] and "tumble" not in found["differences"]
    assert found["nearest"] == "exponential-map" and found["difference"] == 0.0
    assert rotation_engines._identified(found) == "none (diverged on tumble)"


def test_mujoco_euler_on_a_free_body_is_the_exponential_map_to_round_off(references):
    """The finding itself: MuJoCo's Euler is steplab's exponential-map, alone of the eight, to 1e-13."""
    needs("mujoco")
    found = rotation_engines.identify(ROTATION_SETTINGS["mujoco-euler"], rotation_engines.parameters(True),
                                      references)
    assert found["equals"] == ["exponential-map"] and found["difference"] < 1e-13
    others = {m: d for m, d in found["differences"]["tumble"].items() if m != "exponential-map"}
    assert min(others.values()) > 1e-4  # the nearest other method is far beyond round-off


@pytest.mark.parametrize("engine", ["box2d", "chipmunk"])
def test_a_spin_in_the_x_z_plane_is_the_exact_rotation(engine):
    """A box falling in the x-z plane (gravity along -z) while it spins about y: the engine's
    orientation after n steps is the exact exp(omega t) q0, and its spin stays omega. The
    engine's counter-clockwise angle turns x towards z, a rotation about -y: the sign is tested."""
    needs(engine)
    dt, n, spin = 0.01, 50, -3.0
    q0 = quat.from_axis_angle(np, np.array([0.0, 1.0, 0.0]), 0.4)
    _, bodies = tilted_box(np.array([0.0, spin, 0.0]), q0)
    model = Model([MASS], [0.05], [Gravity()])
    y0 = np.zeros((2, 1, 3))
    run = build(engine, model, None, dt, y0, bodies=bodies)
    assert run.axes == (0, 2)
    _, rotation = run.advance_rotating(y0, dt, n)
    exact = quat.multiply(np, quat.from_axis_angle(np, np.array([0.0, 1.0, 0.0]), spin * n * dt), q0)
    tolerance = 1e-5 if ENGINES[engine].precision == "float32" else 1e-13
    assert quat.angle_between(np, rotation.orientations[-1, 0], exact) < tolerance
    np.testing.assert_allclose(rotation.angular_velocities[-1, 0], [0.0, spin, 0.0], atol=tolerance)


@pytest.mark.parametrize("engine", ["box2d", "chipmunk"])
def test_a_planar_engine_refuses_a_tumble_in_one_line(engine):
    needs(engine)
    model, bodies = tilted_box()
    with pytest.raises(UnsupportedFeatureError) as err:
        build(engine, model, None, 0.01, np.zeros((2, 1, 3)), bodies=bodies)
    assert "\n" not in str(err.value) and "turns bodies only about the axis out of its plane" in str(err.value)


def test_the_engines_record_and_its_figure(tmp_path):
    """measure() with MuJoCo's Euler: its drift is the exponential map's, its row in the table, its
    figure; an engine that is missing is named in one line, and the others are measured."""
    needs("mujoco")
    from steplab.studies.rotation import BULLET_OMEGA, _style, bullet_body

    params = rotation_engines.parameters(True) | {"settings": ["mujoco-euler"], "identification_steps": 20,
                                                  "drift_time": 2.0, "drift_saves": 4}
    record = rotation_engines.measure(params, (bullet_body().tolist(), list(BULLET_OMEGA)))
    drift = {(r["body"], r["name"]): r for r in record["drift"]}
    for body in ("flip box", "Bullet demo body"):
        engine, method = drift[(body, "mujoco-euler")], drift[(body, "exponential-map")]
        np.testing.assert_allclose(engine["energy"], method["energy"], rtol=0, atol=1e-12)
    assert record["missing"] is None
    table = rotation_engines.engines_table(record)
    assert "| MuJoCo Euler | exponential-map | exponential-map |" in table
    assert rotation_engines.plot(record, tmp_path, _style) == ["rotation_engines.png", "rotation_engines.svg"]
    # an engine that diverged on every problem, first: it has no distances, and the figure still draws
    lost = record["identification"][0] | {"differences": {}, "diverged": ["tumble", "spin"], "nearest": None,
                                         "difference": None, "equals": []}
    record["identification"].insert(0, lost)
    assert rotation_engines.plot(record, tmp_path, _style) == ["rotation_engines.png", "rotation_engines.svg"]
    assert "| MuJoCo Euler | exponential-map | none (diverged on tumble, spin) | none |" in \
        rotation_engines.engines_table(record)


def test_a_missing_engine_is_one_line_and_the_rest_run(monkeypatch):
    needs("mujoco")
    monkeypatch.setattr(ENGINES["chipmunk"], "available", classmethod(lambda cls: False))
    params = rotation_engines.parameters(True) | {"settings": ["chipmunk"], "identification_steps": 5,
                                                  "drift_time": 1.0, "drift_saves": 1}
    record = rotation_engines.measure(params, ([1.0, 2.0, 3.0], [0.0, 0.1, 10.0]))
    assert record["settings"] == [] and record["identification"] == []
    assert "pymunk" in record["missing"] and "\n" not in record["missing"]
