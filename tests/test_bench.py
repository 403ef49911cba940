"""``steplab bench``: its comparisons compute the same thing, and its record has every key.

No wall-clock assertion here (timings belong in the benchmark): the peers must reach the
same final state as steplab for the same method, dt and steps, and a tiny bench run must
produce the JSON contract of issue 6.
"""

import dataclasses
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from steplab.integrators import RK4
from steplab.integrators.simulate import final_state_function
from steplab.physics import Drag, Friction, Gravity, Model
from steplab.physics.scene import load_scene
from steplab.studies.problems import oscillator_problem

from steplab import bench, peers
from steplab.cli import main

#: a bench run small enough for a unit test (seconds, not minutes)
TINY = bench.Config(small_steps=300, particles=500, cloth_side=6, broadphase_n=2_000, periods=1,
                    max_log2_steps=14, batch=3, batch_steps=50, repeats=1, python_repeats=1, python_steps=50,
                    loop_steps=2, compile_scenes=("projectile", "spring-pendulum"),  # an attached scene's step
                    collision_runs=((30, 3),), max_rounds=4,
                    round_budget_seconds=1.0, stack_pyramid_rows=3, stack_steps=1,
                    box_pit_runs=((30, 2),), crowded_pit=(30, 1.0, 2))
#: final states of the same method, dt and steps agree to this (m, m/s): round-off only
ROUND_OFF = 1e-12


def _steplab_final(model, method, y0, dt, n):
    import jax.numpy as jnp

    run = final_state_function(model.cast(jnp), method)
    y, bad = run(jnp.asarray(y0), 0.0, dt, n)
    assert int(bad) == -1
    return np.asarray(y)


def test_semi_implicit_euler_peers_reach_steplabs_state():
    import jax.numpy as jnp

    problem = oscillator_problem(0.0)
    dt, n = 1e-3, 400
    ours = _steplab_final(problem.model, "semi-implicit-euler", problem.y0, dt, n)
    theirs, steps = peers.diffrax_fixed_step(problem.model.cast(jnp), "semi-implicit-euler", 0.0, dt, n)(
        jnp.asarray(problem.y0))
    assert int(steps) == n
    system = peers.PointMasses.from_model(problem.model)
    for other in (theirs, peers.numba_semi_implicit_euler(system, problem.y0, dt, n),
                  peers.numpy_semi_implicit_euler(system, problem.y0, dt, n)):
        np.testing.assert_allclose(np.asarray(other), ours, rtol=0, atol=ROUND_OFF)
    assert not np.allclose(ours, problem.y0)  # it moved


@pytest.mark.parametrize("method", ["euler", "rk4"])
def test_diffrax_counterparts_reach_steplabs_state(method):
    import jax.numpy as jnp

    scene = load_scene("drag-projectile")  # nonlinear: drag depends on |v|
    dt, n = 0.01, 100
    ours = _steplab_final(scene.model, method, scene.y0, dt, n)
    theirs, steps = peers.diffrax_fixed_step(scene.model.cast(jnp), method, 0.0, dt, n)(jnp.asarray(scene.y0))
    assert int(steps) == n
    np.testing.assert_allclose(np.asarray(theirs), ours, rtol=1e-13, atol=ROUND_OFF)


def test_adaptive_peers_count_a_failed_solve_as_missing_the_tolerance(monkeypatch):
    """A solve that ran out of steps stops short of t_end; the tolerance search must not take the
    state where it stopped for an answer (it may lie near the truth)."""
    import jax.numpy as jnp
    from steplab.integrators.references import AdaptiveSolution

    from steplab.bench import comparisons

    problem = oscillator_problem(0.0, t_end=1.0)
    truth = np.asarray(problem.y0, float)  # stopped at the start: as near the truth of a whole period as can be
    failed = AdaptiveSolution(np.asarray([problem.y0]), 1, 6, False, "budget")
    assert comparisons._solved_error(failed, truth) == np.inf
    assert comparisons._solved_error(failed._replace(success=True), truth) == 0.0

    model = problem.model.cast(jnp)
    monkeypatch.setattr(peers, "ADAPTIVE_MAX_STEPS", 3)
    y, steps = peers.diffrax_adaptive(model, "diffrax-tsit5", 0.0, 10.0)(jnp.asarray(problem.y0), jnp.asarray(1e-12))
    assert int(steps) == 3 and np.all(np.asarray(y) == np.inf)
    monkeypatch.undo()
    y, _ = peers.diffrax_adaptive(model, "diffrax-tsit5", 0.0, 10.0)(jnp.asarray(problem.y0), jnp.asarray(1e-10))
    assert np.all(np.isfinite(np.asarray(y)))


def test_diffrax_rk4_tableau_is_steplabs():
    tableau = peers.diffrax_rk4().tableau
    ours = RK4.tableau
    assert [list(row) for row in tableau.a_lower] == [list(row) for row in ours.a_lower]
    assert list(tableau.b_sol) == list(ours.b) and list(tableau.c) == list(ours.c)
    assert peers.diffrax_rk4().order(None) == 4


def test_numba_loop_reaches_steplabs_state_with_every_supported_force():
    model, y0, _ = bench.cloth_model(5)  # gravity, springs, dampers, pinned corners
    system = peers.PointMasses.from_model(model)
    ours = _steplab_final(model, "semi-implicit-euler", y0, 5e-4, 200)
    np.testing.assert_allclose(peers.numba_semi_implicit_euler(system, y0, 5e-4, 200), ours, rtol=0, atol=1e-11)
    np.testing.assert_allclose(peers.numpy_semi_implicit_euler(system, y0, 5e-4, 200), ours, rtol=0, atol=1e-11)
    model, y0 = bench.particles_model(50)  # gravity and drag
    system = peers.PointMasses.from_model(model)
    ours = _steplab_final(model, "semi-implicit-euler", y0, 1e-3, 100)
    np.testing.assert_allclose(peers.numba_semi_implicit_euler(system, y0, 1e-3, 100), ours, rtol=0, atol=1e-11)


def test_peers_refuse_forces_they_do_not_model():
    model = Model([1.0], [0.1], [Gravity(), Friction(0.5, 0.3, np.array([0.0, 0.0, 1.0]), 0.0, np.array([0.1]))])
    with pytest.raises(ValueError, match="friction"):
        peers.PointMasses.from_model(model)
    assert peers.PointMasses.from_model(Model([1.0], [0.1], [Drag(np.array([0.2]))])).beta.tolist() == [0.2]


def test_memory_bound_streams_the_bytes_it_claims():
    model, _ = bench.particles_model(1000)
    system = peers.PointMasses.from_model(model)
    # q and v read and written (2 x N x 3 doubles), 1/m and drag beta only read (2 x N doubles)
    assert bench.step_bytes(model, system) == (2 * 1000 * 3 * 8, 2 * 1000 * 8)
    peers.memory_stream(48_000, 16_000)()


@pytest.fixture(scope="module")
def tiny_record():
    with pytest.MonkeyPatch.context() as patch:  # a real-time target on the tiny ball pit too
        patch.setitem(bench.REAL_TIME_TARGETS, 30, 0.25)
        return bench.run_bench(TINY, quick=True)


def test_tiny_bench_run_has_the_json_contract(tiny_record):
    record = json.loads(json.dumps(tiny_record))  # JSON-able
    assert set(bench.REQUIRED_RATIOS) <= set(record["ratios"])
    expected = {"vs_diffrax_euler", "vs_diffrax_rk4", "vs_python_loop_semi_implicit_euler", "vs_numba_1e6",
                "vs_memory_bound_cloth_1e5_springs", "vs_numba_cloth_1e5_springs", "vs_diffrax_tsit5_at_1e-8",
                "batched_vs_loop_initial_conditions", "batched_vs_loop_dt", "batched_vs_loop_springs"}
    assert expected <= set(record["ratios"])
    for name, ratio in record["ratios"].items():
        seconds = record["seconds"][name]
        assert seconds["steplab"] > 0 and seconds["peer"] > 0, name
        assert ratio == pytest.approx(seconds["steplab"] / seconds["peer"]), name
    for name, target in record["targets"].items():
        measured = target.get("ratio") or target.get("seconds") or target.get("us_per_impact")
        assert target["met"] == (measured <= target["target"]), name
    assert set(bench.TARGETS) | {"compile_seconds_max"} <= set(record["targets"])
    assert record["compile_seconds"] and record["provenance"]["packages"]["jax"]


def test_tiny_bench_run_records_the_spread_of_every_side(tiny_record):
    for name, seconds in tiny_record["seconds"].items():
        for side in ("steplab", "peer"):
            spread = seconds[f"{side}_spread"]
            assert 0 < spread["min"] <= spread["median"] <= spread["max"], (name, side)
            # the fields other code reads are the spread's
            assert (seconds[side], seconds[f"{side}_min"]) == (spread["median"], spread["min"]), (name, side)
        assert seconds["ratio_stable"] == (seconds["stability_note"] is None), name
    markdown = bench.format_markdown(tiny_record)
    assert "steplab min / median / max" in markdown.splitlines()[0]
    s = tiny_record["seconds"]["vs_memory_bound_1e6"]
    assert bench.report._spread(s["steplab_spread"]) in markdown


def test_memory_bounds_keep_the_step_against_one_compiled_pass_beside_them(tiny_record):
    # the targets stay on NumPy's two passes; the same bytes moved in one compiled pass, a tighter
    # bound, are timed in the same rounds and printed under the table
    [line] = [line for line in bench.format_table(tiny_record).splitlines() if "tighter memory bound" in line]
    for name in ("vs_memory_bound_xpbd_cloth", "vs_memory_bound_rotation_1e5"):
        tighter = tiny_record["seconds"][name]["compiled_stream"]
        assert tighter["bound"] > 0 and tighter["ratio"] == pytest.approx(tighter["steplab"] / tighter["bound"])
        assert f"{name} {tighter['ratio']:.3g}x" in line
    # the cloth's pass is timed in the step's own cold rounds: its step is the target's, on its own clock
    cloth = tiny_record["seconds"]["vs_memory_bound_xpbd_cloth"]
    tighter = cloth["compiled_stream"]
    assert tighter["steplab"] == cloth[f"steplab_{tighter['clock']}_spread"]["median"]
    # and the warm step against the target's own cold bound: its bound is the target's peer, its step the
    # warm pair's (each side on the clock the pair shares)
    room = cloth["warm_step_against_cold_bound"]
    assert room["bound"] == cloth[f"peer_{room['clock']}_spread"]["median"]
    assert room["ratio"] == pytest.approx(room["steplab"] / room["bound"])
    if room["clock"] == cloth["warm"]["clock"]:
        assert room["steplab"] == cloth["warm"]["steplab"]


def test_one_section_runs_alone_and_says_so(tiny_record):
    # judging a ratio that moves between processes takes several runs of its section alone
    assert "xpbd-cloth" in bench.section_names() and len(set(bench.section_names())) == len(bench.SECTIONS)
    performance = (Path(__file__).resolve().parent.parent / "docs" / "performance.md").read_text()
    assert all(f"`{name}`" in performance for name in bench.section_names())  # the page lists them all
    record = bench.run_bench(TINY, quick=True, only=["broadphase"])
    assert set(record["ratios"]) == {n for n, s in tiny_record["seconds"].items() if s["group"] == "broadphase"}
    assert list(record["details"]["section_seconds"]) == ["broadphase"] and record["details"]["only"] == ["broadphase"]
    assert "quick (only broadphase) run" in bench.format_table(record)
    assert tiny_record["details"]["only"] is None and "quick run" in bench.format_table(tiny_record)
    with pytest.raises(ValueError, match="no section nope; the sections: small-system"):
        bench.run_bench(TINY, quick=True, only=["nope"])


def test_bench_only_names_a_section_or_fails_in_one_line(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["bench", "--only", "nope"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "invalid choice: 'nope'" in err and "'xpbd-cloth'" in err


def _xpbd_run(ratio: float) -> dict:
    """A record of one xpbd comparison whose ratio is ``ratio`` (its target 1.5)."""
    record = bench.Record(TINY, quick=True)
    record.compare("vs_memory_bound_xpbd_cloth", "cloth (XPBD)", "what", "bound", bench.Times.of([ratio]),
                   bench.Times.of([1.0]))
    return record.data


def test_repeat_summarises_each_ratio_over_its_runs():
    from steplab.bench.repeat import format_summary, summary

    runs = [_xpbd_run(r) for r in (1.4, 1.6, 1.45)]
    [row] = summary(runs)
    assert row["ratios"] == pytest.approx([1.4, 1.6, 1.45])
    assert (row["min"], row["median"], row["max"]) == pytest.approx((1.4, 1.45, 1.6))
    assert (row["target"], row["met_runs"], row["median_met"]) == (1.5, 2, True)
    text = format_summary({"repeat": 3, "arguments": ["bench", "--only", "xpbd-cloth"], "runs": runs,
                           "summary": [row]})
    assert "2 of 3 runs; the median meets it" in text and "3 runs of `steplab bench --only xpbd-cloth`" in text
    markdown = format_summary({"repeat": 3, "arguments": ["bench"], "runs": runs, "summary": [row]}, markdown=True)
    assert "| cloth (XPBD) | vs_memory_bound_xpbd_cloth | 3 | 1.4 | 1.45 | 1.6 | ≤ 1.5 | 2 of 3 runs;" in markdown
    assert summary([_xpbd_run(r) for r in (1.6, 1.45)])[0]["median_met"] is False  # median 1.525


def test_bench_repeat_runs_each_in_a_fresh_process_and_summarises_them(capsys, tmp_path, monkeypatch):
    monkeypatch.delenv("EQX_ON_ERROR", raising=False)  # restored after the test: other tests need diffrax to raise
    path = tmp_path / "repeat.json"
    assert main(["bench", "--quick", "--only", "batching", "--repeat", "2", "--json", str(path)]) == 0
    result = json.loads(path.read_text())
    runs = result["runs"]
    assert result["repeat"] == 2 and len(runs) == 2 and all(r["details"]["only"] == ["batching"] for r in runs)
    assert len({r["details"]["total_seconds"] for r in runs}) == 2  # two runs, not one record twice
    for row in result["summary"]:
        ratios = [r["ratios"][row["name"]] for r in runs]
        assert row["ratios"] == ratios and row["median"] == pytest.approx(sum(ratios) / 2)
    out = capsys.readouterr().out
    assert all(row["name"] in out for row in result["summary"]) and "2 runs of `steplab bench --quick" in out
    assert main(["bench", "--from", str(path)]) == 0 and capsys.readouterr().out == out  # re-printed from the record


@pytest.mark.parametrize(("argv", "message"), [(["--repeat", "0"], "must be a positive integer, got 0"),
                                               (["--repeat", "2", "--from", "x.json"], "give one of them")])
def test_bench_repeat_refuses_bad_input_in_one_line(capsys, argv, message):
    try:
        status = main(["bench", *argv])
    except SystemExit as exit_:  # argparse's own refusal
        status = exit_.code
    err = capsys.readouterr().err.strip()
    assert status == 2 and len(err.splitlines()) == 1 and message in err


@pytest.mark.parametrize(("text", "message"), [
    ("host\n", "not JSON (Expecting value"),
    ("[1, 2]", "not a record of `steplab bench --json`"),
    ('{"study": "truncation", "parameters": {}}', "not a record of `steplab bench --json`"),  # a study's record
    ('{"order": [], "seconds": {}, "ratios": {}, "targets": {}}', "without what its table needs (KeyError"),
    ('{"runs": [], "summary": []}', "without what its table needs (KeyError"),
])
def test_bench_from_refuses_a_file_that_is_not_its_record_in_one_line(capsys, tmp_path, text, message):
    path = tmp_path / "record.json"
    path.write_text(text)
    status = main(["bench", "--from", str(path)])
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert status == 2 and captured.out == "" and len(err.splitlines()) == 1
    assert f"--from {path}: " in err and message in err


def test_bench_refuses_a_record_path_it_cannot_write_before_it_runs(capsys, tmp_path, monkeypatch):
    """A full bench takes a quarter of an hour: a --json it could not write must fail first, in one line."""
    for name in ("pin_threads", "fair_diffrax", "run_bench"):
        monkeypatch.setattr(bench, name, lambda *a, **k: pytest.fail("ran before checking --json"))
    (tmp_path / "file").write_text("")
    for path, message in ((tmp_path / "file" / "bench.json", "--json's folder " + str(tmp_path / "file") + ": a file"),
                          (tmp_path, "a folder; give the record's file name")):
        status = main(["bench", "--quick", "--json", str(path)])
        err = capsys.readouterr().err.strip()
        assert status == 2 and len(err.splitlines()) == 1 and message in err


def test_record_says_where_a_ratio_cannot_be_trusted():
    record = bench.Record(TINY, quick=True)
    steady, noisy = bench.Times.of([1.0, 1.01, 1.02]), bench.Times.of([1.0, 1.5, 2.0])
    record.compare("steady", "g", "what", "peer", steady, steady)
    record.compare("noisy", "g", "what", "peer", steady, noisy)
    assert record.data["seconds"]["steady"]["ratio_stable"] is True
    assert record.data["seconds"]["noisy"]["ratio_stable"] is False
    assert "peer's median 50% above its minimum" in record.data["seconds"]["noisy"]["stability_note"]


def _busy(seconds: float) -> None:
    """Spend ``seconds`` of this thread's CPU time (however long that takes on a loaded machine)."""
    end = time.thread_time() + seconds
    while time.thread_time() < end:
        pass


def test_cpu_time_leaves_out_waiting_and_keeps_the_work():
    from steplab.core.timing import Times, interleaved_samples

    samples = interleaved_samples({"asleep": lambda: time.sleep(0.05), "busy": lambda: _busy(0.02)}, 3)
    # asleep: 50 ms of wall time and next to no CPU time (what a preempted call looks like)
    assert min(samples["asleep"]) >= 0.05 and max(samples["asleep"].cpu) < 0.01
    # busy: at least the 20 ms of CPU spent, and no more CPU than wall time on one thread
    assert min(samples["busy"].cpu) >= 0.02
    assert all(c <= w * 1.05 + 1e-3 for c, w in zip(samples["busy"].cpu, samples["busy"], strict=True))
    times = Times.of(samples["busy"])
    assert times.cpu.minimum >= 0.02 and times.cpu.rounds == 3 and times.faults is not None
    assert times.scaled(0.5).cpu.median == pytest.approx(times.cpu.median / 2)


def test_cpu_time_of_a_call_leaves_out_work_another_thread_left_behind():
    # as JAX's worker thread goes on releasing a call's buffers after block_until_ready: the
    # next contender's CPU time must not carry it (the timer waits for the threads to be idle)
    import threading

    from steplab.core.timing import interleaved_samples

    def leaves_work_behind():
        threading.Thread(target=_busy, args=(0.02,)).start()

    samples = interleaved_samples({"leaves": leaves_work_behind, "idle": lambda: None}, 3, warm_up=False)
    assert max(samples["idle"].cpu) < 0.005


def test_ratio_is_on_cpu_time_where_both_sides_ran_on_one_thread():
    from steplab.core.timing import Samples

    record = bench.Record(TINY, quick=True)
    # steplab preempted in two rounds of three (wall 2x), its CPU steady; the peer undisturbed
    steplab = bench.Times.of(Samples([1.0, 2.0, 2.0], [1.0, 1.01, 1.0], [0] * 3, [0, 9, 9]))
    peer = bench.Times.of(Samples([2.0, 2.0, 2.0], [2.0, 2.0, 2.0], [0] * 3, [0] * 3))
    record.compare("one thread", "g", "what", "peer", steplab, peer)
    s = record.data["seconds"]["one thread"]
    assert s["clock"] == "cpu" and record.data["ratios"]["one thread"] == pytest.approx(0.5)
    assert s["ratio_wall"] == pytest.approx(1.0) and s["ratio_stable"] and s["steplab_preempted"] == 9
    assert (s["steplab"], s["steplab_wall_spread"]["median"]) == (1.0, 2.0)
    # a side on two threads (twice the CPU seconds of its wall seconds): its CPU time is not its speed
    threads = bench.Times.of(Samples([1.0, 1.0, 1.0], [2.0, 2.0, 2.0], [0] * 3, [0] * 3))
    record.compare("two threads", "g", "what", "peer", threads, peer)
    assert record.data["seconds"]["two threads"]["clock"] == "wall"
    assert record.data["ratios"]["two threads"] == pytest.approx(0.5)


class _Clock:
    """A fake ``time.perf_counter`` that a call advances by the seconds it says it took."""

    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now

    def call(self, seconds):
        def advance():
            self.now += next(seconds) if hasattr(seconds, "__next__") else seconds
        return advance


def test_settled_samples_stop_when_the_minimums_settle(monkeypatch):
    from steplab.bench import timing

    clock = _Clock()
    monkeypatch.setattr(time, "perf_counter", clock)  # the wall clock of a loaded machine is no test
    calls = {"a": clock.call(2e-3), "b": clock.call(1e-3)}
    samples = timing.settled_samples(calls, 2, 50, 60.0)
    assert len(samples["a"]) == len(samples["b"]) == timing.PATIENCE + 1  # settled at the first look
    assert samples["a"] == pytest.approx([2e-3] * len(samples["a"]))
    assert len(timing.settled_samples(calls, 2, 3, 60.0)["a"]) == 3  # the budget of rounds holds
    # a side whose every round is much faster than the last never settles: the budget stops it
    shrinking = {"shrinking": clock.call(iter(np.geomspace(0.03, 0.0003, 13)))}
    assert len(timing.settled_samples(shrinking, 2, 12, 60.0)["shrinking"]) == 12
    # and the budget of seconds: rounds of 1 s within 5.5 s
    assert len(timing.settled_samples({"slow": clock.call(iter(np.geomspace(1.0, 0.5, 30)))}, 2, 30, 5.5)["slow"]) \
        in (5, 6)


def test_marginal_cost_leaves_out_the_fixed_cost_of_a_call():
    from steplab.bench import timing

    # calls of k and 2k steps of 5 ms behind a 100 ms fixed cost (the 10^6-particle call's
    # fresh output), each round slowed by a preemption of 0 to 8 ms on one of its calls
    k, step, fixed = 32, 5e-3, 0.1
    delays = np.array([0.0, 4e-3, 8e-3, 0.0, 4e-3])
    once, twice = fixed + k * step + delays, fixed + 2 * k * step + delays[::-1]
    times, how = timing.marginal_times(once, twice, k)
    assert how == "marginal" and times.minimum == pytest.approx(step)  # the undisturbed calls
    assert times.minimum <= times.median <= times.maximum == pytest.approx(step + 4e-3 / k)
    # noise larger than k steps: the average over 2k steps, an upper bound, and said so
    times, how = timing.marginal_times(once + [0.0, 0.0, 0.5, 0.0, 0.0], twice, k)
    assert how.startswith("average") and times.minimum >= step


def test_marginal_cost_on_cpu_time_leaves_out_the_preemptions():
    from steplab.bench import timing
    from steplab.core.timing import Samples

    # calls of k and 2k steps of 5 ms behind a 100 ms fixed cost; the wall clock also counts
    # 0 to 40 ms of other processes' slices, the CPU clock does not
    k, step, fixed = 32, 5e-3, 0.1
    lost = np.array([0.0, 0.04, 0.02, 0.0, 0.04])
    cpu_once, cpu_twice = np.full(5, fixed + k * step), np.full(5, fixed + 2 * k * step)
    once = Samples(cpu_once + lost, cpu_once, [0] * 5, [0, 10, 5, 0, 10])
    twice = Samples(cpu_twice + lost[::-1], cpu_twice, [0] * 5, [10, 10, 5, 0, 0])
    times, how = timing.marginal_times(once, twice, k)
    assert how == "marginal" and times.maximum > 1.2 * step  # the wall clock's rounds move
    assert times.cpu.minimum == pytest.approx(step) and times.cpu.maximum == pytest.approx(step)
    assert times.threads <= 1.0 and times.preempted == 5.0


def test_bench_pins_one_thread_per_side_in_the_timed_process():
    # a fresh process, as ``steplab bench`` is: pinned before JAX and Numba are imported,
    # then the timing helper runs a compiled call and reports the settings it ran with
    script = (
        "import json, os\n"
        "os.environ.pop('XLA_FLAGS', None); os.environ['NUMBA_NUM_THREADS'] = '2'\n"
        "from steplab.bench import timing\n"
        "assert timing.pin_threads()\n"
        "import jax, jax.numpy as jnp, numba\n"
        "timing.settled_samples({'jax': lambda: jnp.ones(1000).sum().block_until_ready()}, 2, 4, 5.0)\n"
        "print(json.dumps(timing.thread_settings()))\n")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout
    settings = json.loads(out.splitlines()[-1])
    assert settings["pinned"] and settings["numba_threads"] == 1
    assert settings["cores"] in (None, 1)  # one core where the OS can set it: XLA's flags alone left it two threads
    assert "--xla_cpu_multi_thread_eigen=false" in settings["XLA_FLAGS"].split()
    assert "intra_op_parallelism_threads=1" in settings["XLA_FLAGS"].split()
    # too late after JAX: the helper says so rather than pretending
    late = ("import os, jax\nfrom steplab.bench import timing\nos.environ.pop('XLA_FLAGS', None)\n"
            "print(timing.pin_threads(), os.environ.get('XLA_FLAGS'))\n")
    assert subprocess.run([sys.executable, "-c", late], capture_output=True, text=True,
                          check=True).stdout.split() == ["False", "None"]


def test_tiny_bench_run_compared_equal_computations(tiny_record):
    differences = {name: s["difference"] for name, s in tiny_record["seconds"].items()
                   if s["difference"] is not None}
    assert differences["vs_ckdtree_1e5"] == 0  # the same pairs
    for name, difference in differences.items():
        assert difference <= 1e-9, name
    accuracy = tiny_record["seconds"]["vs_scipy_at_1e-8"]
    assert accuracy["steplab_error"] <= 1e-8 and accuracy["peer_error"] <= 1e-8


def test_tiny_bench_run_measures_the_ball_pit(tiny_record):
    pit = tiny_record["collisions"]["ball_pit_30"]
    assert (pit["balls"], pit["steps"], pit["dt"]) == (30, 3, 1 / 60)
    for name, c in pit["contenders"].items():
        assert 0 < c["wall_seconds"] < np.inf and c["balls_inside"] == 30, name
        assert c["per_step_seconds"] == pytest.approx(c["wall_seconds"] / 3)
        assert c["real_time_factor"] == pytest.approx(3 / 60 / c["wall_seconds"])
        if name == "steplab_solver":  # 4 substeps: semi-implicit Euler falls g dt^2 k (1 - 1/4) / 2 less in k steps
            assert c["median_distance_to_steplab"] == pytest.approx(9.81 / 60**2 * 3 * 0.75 / 2, rel=1e-6)
        elif name != "steplab":  # balls in free flight move alike: the engines started from the same state
            assert c["median_distance_to_steplab"] <= 1e-3, name
            assert tiny_record["ratios"][f"vs_{name}_ball_pit_30"] > 0
    assert (set(pit["contenders"]) | set(pit["not_compared"])
            == {"steplab", "steplab_solver", *bench.engines.peer_names()})
    assert pit["contenders"]["steplab"]["impacts"] >= 0
    target = tiny_record["targets"]["real_time_ball_pit_30"]
    assert target["target"] == 4.0 and target["seconds"] == pytest.approx(1 / target["real_time_factor"])
    assert "ball_pit_30" in bench.format_table(tiny_record) and "`ball_pit_30`" in bench.format_markdown(tiny_record)
    # the crowded pit times its contenders only (no balls inside, no impacts): its rows print all the same
    markdown, table = bench.format_markdown(tiny_record), bench.format_table(tiny_record)
    assert "`crowded_pit_30`" in markdown and "crowded_pit_30" in table


def test_box_pits_print_their_real_time_and_the_target_on_the_run_that_judged_it(tiny_record):
    from steplab.bench.report import box_pit_rows

    markdown, table = bench.format_markdown(tiny_record), bench.format_table(tiny_record)
    assert "`box_pit_30`" in markdown and "\nbox_pit_30 " in table
    record = json.loads(json.dumps(tiny_record))  # a 2-core run of the tiny pit judged, as the 10^4 pit's is
    pit = record["stacking"]["box_pit_30"]
    pit["real_time_factor"]["steplab_2_cores"] = 0.5
    pit["cores"]["steplab_2_cores"] = 2
    pit["on_cores"] = {"cores": 2, "settings": "steplab, 2 threads"}
    record["targets"]["real_time_box_pit_30"] = {"target": 1.0, "met": False, "real_time_target": 1.0, "cores": 2}
    rows = [r for r in box_pit_rows(record) if r["pit"] == "box_pit_30"]
    judged = [r for r in rows if r["target"] is not None]
    assert [(r["contender"], r["cores"], r["real_time_factor"]) for r in judged] == [("steplab, 2 threads", 2, 0.5)]
    assert "| `box_pit_30` | 30 | 2 | steplab, 2 threads | 2 | 0.5 | ≥ 1x: missed |" in bench.format_markdown(record)
    # the judged run is the median of several processes: each one's real-time factor beside it
    pit["on_cores"]["processes"] = [{"median": 1 / 60 / f, "real_time_factor": f} for f in (0.6, 0.5, 0.4)]
    contender = "steplab, 2 threads (the median of 3 processes: 0.6, 0.5, 0.4x real time)"
    assert f"| `box_pit_30` | 30 | 2 | {contender} | 2 | 0.5 | ≥ 1x: missed |" in bench.format_markdown(record)


def test_ball_pit_scene_files_are_the_generators():
    from steplab.bench import ball_pit_scene as pit

    folder = Path(__file__).parent.parent / "benchmarks" / "scenes"
    for n in pit.SCENE_FILE_SIZES:  # regenerate with steplab.bench.ball_pit_scene.write_scene_files
        assert (folder / pit.scene_file_name(n)).read_text() == pit.ball_pit_toml(n), n
    scene = bench.ball_pit(2_000)
    q, v = scene.y0
    half = scene.collisions.shapes[1].offset * -1
    assert scene.model.n_bodies == 2_000 and half == 10.0  # the issue's sparse 20 m box
    assert np.all(np.abs(q[:, :2]) <= half - pit.RADIUS) and np.all(q[:, 2] >= pit.RADIUS)
    assert np.all(np.linalg.norm(v, axis=1) <= pit.SPEED)


def test_bench_command_writes_json_and_prints_tables(tiny_record, monkeypatch, tmp_path, capsys):
    monkeypatch.delenv("EQX_ON_ERROR", raising=False)  # restored after the test: other tests need diffrax to raise
    runs = []
    monkeypatch.setattr(bench, "run_bench", lambda config, quick, progress, only: runs.append(config) or tiny_record)
    out = tmp_path / "bench.json"
    assert main(["bench", "--quick", "--json", str(out)]) == 0
    assert runs == [bench.QUICK]
    table = capsys.readouterr().out
    assert "vs_diffrax_semi_implicit_euler" in table and "ratio" in table
    assert json.loads(out.read_text())["ratios"] == tiny_record["ratios"]
    assert main(["bench", "--from", str(out), "--markdown"]) == 0
    markdown = capsys.readouterr().out
    assert markdown.startswith("| comparison |") and "`vs_memory_bound_1e6`" in markdown


def test_quick_bench_keeps_the_issues_sizes():
    # --quick shortens repeats, not the systems the targets are stated for
    for field in ("small_steps", "particles", "broadphase_n"):
        assert getattr(bench.QUICK, field) == getattr(bench.FULL, field)
    assert dataclasses.asdict(bench.FULL)["small_steps"] == 100_000
