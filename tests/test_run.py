"""The one run loop (:mod:`raybundle.imaging.run`): the budget it owns, its stop, its slices, on a real
solver and renderer."""
import threading
import time

import pytest

from raybundle.app import pipeline
from raybundle.imaging.run import RunLoop, check_budget
from raybundle.imaging.settings import RenderSettings
from raybundle.scene import builtin as scenes


@pytest.fixture(scope="module")
def scene():
    return pipeline.prepare(scenes.cornell(resolution=(8, 8)), patches=60)


def solver(scene, seed=0):
    return pipeline.make_solver(scene, RenderSettings(seed=seed))


@pytest.mark.parametrize("iterations,seconds,message", [
    (None, None, "give iterations or a time limit"), (3, 1.0, "not both"), (-1, None, "non-negative"),
    (None, float("inf"), "finite"), (None, -2.0, "non-negative")])
def test_a_budget_that_cannot_run_is_one_line(iterations, seconds, message):
    with pytest.raises(ValueError, match=message):
        check_budget(iterations, seconds)


def test_iterations_in_slices_are_the_iterations_in_one_go(scene):
    """A bake's timer ticks (``advance(max_seconds=...)``) step exactly as one call: the same
    iterations, the same solution."""
    one, sliced = solver(scene, 4), solver(scene, 4)
    try:
        RunLoop(one, iterations=12).advance()
        loop, calls = RunLoop(sliced, iterations=12), 0
        while loop.advance(max_seconds=0.0):
            calls += 1
        assert loop.finished and not loop.cancelled and loop.fraction == 1.0 and calls == 12
        assert one.stats.iterations == sliced.stats.iterations == 12
        assert (one.mean_incoming == sliced.mean_incoming).all()
        assert loop.final_time() is None          # a run of given iterations gathers nothing automatic
    finally:
        one.tracer.close()
        sliced.tracer.close()


def test_a_budget_spent_in_set_up_still_runs_the_minimum_and_says_so(scene):
    s = solver(scene)
    try:
        loop = RunLoop(s, time_limit=0.5, started=time.perf_counter() - 2.0)     # set-up took 2 s of 0.5
        assert loop.iteration_time == 0.0 and loop.setup_seconds >= 2.0
        assert loop.advance() is False and s.stats.iterations == RunLoop.MIN_ITERATIONS
        assert loop.short and "too short" in loop.budget_note(2.5)
    finally:
        s.tracer.close()


def test_the_time_left_after_set_up_is_shared_with_the_final_image(scene):
    """A timed run iterates for (seconds - set-up) / (1 + final share) and leaves the final
    image that share of its iteration time."""
    s = solver(scene)
    try:
        loop = RunLoop(s, time_limit=2.0, started=time.perf_counter() - 0.5, final_share=0.25)
        assert abs(loop.iteration_time - 1.5 / 1.25) < 0.05
        loop.advance()
        # it stops once less than half of its next step is left (a run ends within half a step of its budget)
        assert loop.elapsed() + 0.5 * loop._next_step_seconds() >= loop.iteration_time and not loop.short
        assert abs(loop.final_time() - 0.25 * loop.elapsed()) < 0.01
        # a final image that will not take its share (a gather that would not pay) gives it back
        reserve, before = loop.final_time(), s.stats.iterations
        loop.extend(reserve)
        assert loop.advance() is False and s.stats.iterations > before
        assert loop.elapsed() + 0.5 * loop._next_step_seconds() >= 1.5 / 1.25 + reserve
        assert loop.final_time() == 0.0
    finally:
        s.tracer.close()


def test_a_gather_that_would_not_pay_leaves_its_time_to_the_iterations():
    """On a floor under a lamp no side lies next to a concave edge or contact, so the automatic
    final gather has nothing to serve (``automatic_gather_pays`` is False) and ``Renderer.run``
    gives the seconds it kept for it to iterations: none is gathered."""
    from raybundle.scene.build import build_scene
    from raybundle.scene.camera import Camera
    from raybundle.scene.materials import MaterialTable

    v = [[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0], [-0.2, -0.2, 1], [-0.2, 0.2, 1], [0.2, 0.2, 1], [0.2, -0.2, 1]]
    mats = MaterialTable.from_list([dict(name="floor", diffuse=(0.5, 0.5, 0.5)), dict(name="lamp", emission=(5, 5, 5))])
    cam = Camera.look_at([0, -3, 2], [0, 0, 0], [0, 0, 1], 35.0, 36.0, (16, 16))
    sc = pipeline.prepare(build_scene(v, [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]], [0, 0, 1, 1], mats,
                                      camera=cam), patches=40)
    r = pipeline.make_renderer(sc, RenderSettings(seed=1, resolve_samples=1))
    try:
        r.run(iterations=4)
        assert not r.automatic_gather_pays(10.0)
        res = r.run(time_limit=1.0)
        assert res.stats["gather_rays_per_pixel"] == 0
    finally:
        r.tracer.close()


def test_stop_and_ctrl_c_end_the_loop_with_what_was_done(scene):
    s = solver(scene)
    stop = threading.Event()
    try:
        loop = RunLoop(s, iterations=1000, progress=lambda f, info: stop.set() if info["iterations"] >= 3 else None,
                       stop=stop)
        assert loop.advance() is False and loop.cancelled and s.stats.iterations == 3
        assert loop.final_time() is None

        def interrupt(f, info):
            raise KeyboardInterrupt
        loop = RunLoop(s, time_limit=60.0, progress=interrupt)
        assert loop.advance() is False and loop.cancelled and s.stats.iterations == 4
    finally:
        s.tracer.close()


def test_a_renderer_run_keeps_the_loop_budget(scene):
    """``Renderer.run`` through the loop: the stats carry set-up and total seconds, the
    budget note only when the budget was too short."""
    r = pipeline.make_renderer(scene, RenderSettings(seed=1, resolve_samples=1))
    try:
        res = r.run(iterations=5, started=time.perf_counter() - 1.0)
        assert res.stats["iterations"] == 5 and res.stats["setup_seconds"] >= 1.0 and "budget_note" not in res.stats
        assert res.stats["total_seconds"] >= res.stats["setup_seconds"]
    finally:
        r.tracer.close()


class _Clock:
    """A clock the test advances (``run.time`` replaced: the loop reads ``perf_counter``)."""

    def __init__(self):
        self.now = 100.0

    def perf_counter(self):
        return self.now


class _Stepper:
    """A runner whose steps take 0.1 s, and 2.0 s from ``long_from`` steps on (an image pass
    due), on ``clock``; it says what its next step will take, as a renderer does."""

    def __init__(self, clock, long_from):
        self.clock, self.long_from = clock, long_from
        self.stats = type("Stats", (), {"iterations": 0})()

    def next_step_seconds(self):
        return self._length(self.stats.iterations)

    def _length(self, k):
        return 2.0 if k >= self.long_from else 0.1

    def step(self):
        self.clock.now += self._length(self.stats.iterations)
        self.stats.iterations += 1


def test_a_timed_run_ends_within_half_a_step_of_its_budget(monkeypatch):
    """A 10 s budget whose 100th step would be a long one (2 s, as an image pass of the interior
    bench's hall) starting at 9.9 s: the loop stops before it, since less than half of it is
    left (the runner says what its next step takes), where checking the clock only before a
    step ended the run at 11.9 s; and with the long steps from the 80th on (7.9 s), it stops
    within half a step of the budget (9.9 s, where the old loop took 11.9 s too)."""
    from raybundle.imaging import run

    for long_from, latest in ((99, 10.0), (79, 11.0)):
        clock = _Clock()
        monkeypatch.setattr(run, "time", clock)
        runner = _Stepper(clock, long_from)
        loop = run.RunLoop(runner, time_limit=10.0, started=clock.now)
        loop.advance()
        took = clock.now - 100.0
        assert 9.0 <= took <= latest, (long_from, took)
        assert not loop.short


def _schedule_passes(r, iteration_seconds, pass_seconds, steps):
    """Steps of a timed pass schedule over ``r``'s solver with an iteration of
    ``iteration_seconds`` and a pass of ``pass_seconds`` after a first pass of set-up (3 s): the
    schedule, the number of passes, and the steps whose length it foretold (``next_step_seconds``)."""
    from raybundle.imaging.passes import PassSchedule

    s = PassSchedule(r.solver, r.settings)
    s.by_time = True
    r.solver.stats.iterations = 0
    s.passed(3.0, 0, True)
    passes, rays, foretold = 1, 0, 0
    for _ in range(steps):
        guess = s.next_step_seconds(passes, rays)
        r.solver.stats.iterations += 1
        s.iterated(iteration_seconds)
        k = s.passes_due(passes, rays)
        for _ in range(k):
            s.passed(pass_seconds, 0, False)
        passes += k
        foretold += r.solver.stats.iterations > 1 and abs(guess - iteration_seconds - k * pass_seconds) < 1e-9
    return s, passes - 1, foretold


def test_a_timed_run_shares_time_so_cheaper_passes_buy_more_of_them(scene):
    """``image_share`` 0.5, iterations of 0.1 s: a timed run's passes take as many seconds as its
    iterations, within half a pass, so passes of 0.4 s run every fourth iteration and passes of
    0.025 s four after each; the run loop knows what each step will take.  A run of given
    iterations shares rays, which the clock does not move (it repeats with its seed)."""
    r = pipeline.make_renderer(scene, RenderSettings(seed=1, image_share=0.5, resolve_samples=1))
    try:
        r.run(iterations=4)
        s = r.schedule
        assert not s.by_time

        def due_after(since):
            s.since = since
            return s.passes_due(r.passes, r.image_rays)
        by_rays = [due_after(k) for k in range(8)]
        s.iteration_seconds, s.pass_seconds = 1e-6, 1e6
        assert [due_after(k) for k in range(8)] == by_rays and by_rays[0] == 0 and by_rays == sorted(by_rays)
        RunLoop(r, time_limit=1.0)                 # a timed run's loop shares time
        assert r.schedule.by_time
        for pass_seconds, passes in ((0.4, 25), (0.025, 400)):
            s, n, foretold = _schedule_passes(r, 0.1, pass_seconds, 100)
            # all but the first step, and the one of the first pass after set-up (foretold at set-up's cost)
            assert n == passes and foretold == 98
            assert abs(s.pass_seconds - s.setup_seconds - s.iteration_seconds) <= 0.5 * pass_seconds + 1e-9
    finally:
        r.tracer.close()
