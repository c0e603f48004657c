"""The Python bindings against the rouen command: the same library behind both front ends.

Run by CTest with PYTHONPATH holding the built module and ROUEN_BIN the rouen binary.
"""
import math
import os
import pathlib
import signal
import subprocess
import tempfile
import threading
import unittest

import numpy as np

import rouen

ROUEN_BIN = os.environ.get("ROUEN_BIN", "rouen")
HELD_OUT = 3  # rigs/sim.toml: heldout = "16:00", the fourth of five times


def run_rouen(*args):
    r = subprocess.run([ROUEN_BIN, *map(str, args)], capture_output=True, text=True)
    if r.returncode != 0:
        raise AssertionError(f"rouen {' '.join(map(str, args))} exited {r.returncode}:\n"
                             f"{r.stdout}{r.stderr}")
    return r.stdout + r.stderr


class QuickDemoTest(unittest.TestCase):
    """One quick demo session, solved through the bindings and rendered by both front ends."""

    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.TemporaryDirectory(prefix="rouen-python-")
        cls.dir = os.path.join(cls.tmp.name, "demo")
        run_rouen("demo", "--quick", "--out", cls.dir)
        cls.session_dir = os.path.join(cls.dir, "session")
        cls.lines = []
        cls.events = []
        # The demo's calibration (DIR/work) is reused: same session files and options.
        cls.scene = rouen.solve(rouen.Session(cls.session_dir), os.path.join(cls.tmp.name, "py.scene"),
                                holdout_slots=[HELD_OUT], quick=True,
                                work=os.path.join(cls.dir, "work"), log=cls.lines.append,
                                progress=cls.events.append)

    @classmethod
    def tearDownClass(cls):
        cls.tmp.cleanup()

    def test_session(self):
        s = rouen.Session(self.session_dir)
        self.assertEqual(s.slots, 5)
        self.assertIn("slot0/architecture/view0", s.brackets)
        status = s.status(verify=False)
        self.assertTrue(status["solvable"], status)

    def test_solve_reported_progress_and_wrote_a_scene(self):
        self.assertTrue(any("calib" in line or "response" in line for line in self.lines),
                        self.lines)
        self.assertTrue(os.path.isfile(os.path.join(self.scene.path, "scene.json")))
        self.assertEqual(self.scene.holdout_slots, [HELD_OUT])
        self.assertEqual(len(self.scene.slot_times), 5)
        self.assertEqual(self.scene.config["response"]["max_brackets"], 6)  # quick

    def test_progress_tells_each_stage_in_order(self):
        ends = [e for e in self.events if e["fraction"] == 1]
        starts = [e["stage"] for e in self.events if e["fraction"] == 0]
        self.assertEqual(starts, [e["stage"] for e in ends])
        self.assertEqual(starts[:2], ["model", "lighting"])
        self.assertEqual(starts[-1], "pseudo-albedos")
        self.assertEqual([e["index"] for e in ends], list(range(1, ends[0]["count"] + 1)))
        for e in ends:
            self.assertGreaterEqual(e["figures"]["seconds"], 0, e)
        grid = next(e for e in ends if e["stage"] == "surface grid")
        self.assertIn(f"surface grid: {int(grid['figures']['grid_points'])} points", self.lines)
        lit = [e["fraction"] for e in self.events if e["stage"] == "lighting"]
        self.assertEqual(lit, sorted(lit))
        self.assertEqual(len(lit), 5 + 1)  # the start, then a step per slot (the last its end)

    def test_render_is_the_clis_image(self):
        view = self.scene.views[0]
        for how in (["--slot", "0"], ["--time", self.scene.slot_times[HELD_OUT]]):
            with self.subTest(how=how[0]):
                out = os.path.join(self.tmp.name, f"cli{how[0]}.exr")
                run_rouen("render", self.scene.path, *how, "--view", view, "--out", out)
                cli = rouen.read_image(out)
                if how[0] == "--slot":
                    py = self.scene.render(view=view, slot=0)
                else:
                    py = self.scene.render(how[1], view)
                self.assertEqual(py.dtype, np.float32)
                self.assertEqual(py.shape, cli.shape)
                self.assertTrue(np.isfinite(py).all())
                self.assertGreater(float(py.max()), 0.0)  # the building is lit
                # Bit for bit: one library, and EXR float stores float32 exactly.
                np.testing.assert_array_equal(py, cli)

    def test_second_solve_is_up_to_date(self):
        lines = []
        scene = rouen.solve(self.session_dir, self.scene.path, holdout_slots=[HELD_OUT],
                            quick=True, log=lines.append)
        self.assertTrue(any("up to date" in line for line in lines), lines)
        self.assertEqual(scene.views, self.scene.views)

    def test_validate_matches_the_cli(self):
        figures = self.scene.validate(rouen.Session(self.session_dir), HELD_OUT)
        self.assertTrue(figures["held_out"])
        out = os.path.join(self.tmp.name, "validate.json")
        run_rouen("validate", self.scene.path, "--session", self.session_dir, "--slot", HELD_OUT,
                  "--json", out)
        import json
        with open(out) as f:
            cli = json.load(f)
        for lighting in ("measured", "predicted"):
            py_rmse = figures[lighting]["rel_rmse"]
            self.assertTrue(math.isfinite(py_rmse))
            self.assertAlmostEqual(py_rmse, cli[lighting]["rel_rmse"], places=12)

    def test_errors_raise_rouen_error_naming_the_problem(self):
        with self.assertRaisesRegex(rouen.Error, "no-such-session"):
            rouen.Session(os.path.join(self.tmp.name, "no-such-session"))
        with self.assertRaisesRegex(rouen.Error, "slot0/architecture/view9"):
            self.scene.render(view="slot0/architecture/view9", slot=0)
        with self.assertRaisesRegex(rouen.Error, "slot 7"):
            self.scene.render(slot=7)
        with self.assertRaisesRegex(rouen.Error, "exactly one"):
            self.scene.render("2026-06-21T12:00:00Z", slot=0)
        with self.assertRaisesRegex(rouen.Error, "the options given: sky_fit.no_such_key"):
            rouen.solve(self.session_dir, os.path.join(self.tmp.name, "bad.scene"),
                        config={"sky_fit": {"no_such_key": 1}})
        self.assertFalse(os.path.exists(os.path.join(self.tmp.name, "bad.scene")))

    def test_a_name_too_long_is_a_rouen_error(self):
        # The disk's refusal (ENAMETOOLONG) named as the command names it, found by the hostile
        # probe: it was a bare RuntimeError.
        with self.assertRaisesRegex(rouen.Error, "File name too long"):
            rouen.Session("x" * 5000)

    def test_paths_as_bytes_and_pathlike(self):
        self.assertEqual(rouen.Session(os.fsencode(self.session_dir)).slots, 5)
        self.assertEqual(rouen.Session(pathlib.Path(self.session_dir)).slots, 5)

    def test_a_nan_in_the_config_is_named(self):
        out = os.path.join(self.tmp.name, "nan.scene")
        with self.assertRaisesRegex(rouen.Error, r"config\.grid\.spacing_m = nan is not a finite"):
            rouen.solve(self.session_dir, out, config={"grid": {"spacing_m": float("nan")}})
        self.assertFalse(os.path.exists(out))

    def test_ctrl_c_stops_a_solve_and_writes_no_scene(self):
        out = os.path.join(self.tmp.name, "interrupted.scene")
        lines = []

        def interrupt(line):
            lines.append(line)
            os.kill(os.getpid(), signal.SIGINT)  # as Ctrl-C in the terminal

        with self.assertRaises(KeyboardInterrupt):
            rouen.solve(self.session_dir, out, holdout_slots=[HELD_OUT], quick=True,
                        work=os.path.join(self.tmp.name, "interrupted.work"), log=interrupt)
        self.assertEqual(len(lines), 1, lines)  # stopped at the first line
        self.assertFalse(os.path.exists(out))


    def solve_stopped_after_observations(self, name, stop, lines, **kwargs):
        """A quick solve into `name` (the demo's calibration read back) whose log lines go to
        `lines` and which calls `stop` once the observations are collected, at the start of the
        long stage (irradiance and pseudo-albedos)."""
        def log(line):
            lines.append(line)
            if line.startswith("done: observations"):
                stop()

        rouen.solve(self.session_dir, os.path.join(self.tmp.name, name), holdout_slots=[HELD_OUT],
                    quick=True, work=os.path.join(self.dir, "work"), log=log, **kwargs)

    def assert_stopped_inside_the_stage(self, name, lines):
        self.assertTrue(any(line.startswith("done: observations") for line in lines), lines)
        self.assertFalse(any(line.startswith(("pseudo-albedos", "done: irradiance"))
                             for line in lines), lines)
        self.assertFalse(os.path.exists(os.path.join(self.tmp.name, name)))

    def test_a_cancellation_stops_the_solve_inside_a_stage(self):
        token = rouen.Cancellation()
        self.assertFalse(token.requested)
        lines = []
        # As a stop button would, from another thread; here between two log lines, so that the
        # next poll is inside the stage's work.
        with self.assertRaises(rouen.Cancelled) as raised:
            self.solve_stopped_after_observations("cancelled.scene", token.request, lines,
                                                  cancel=token)
        self.assertIsInstance(raised.exception, rouen.Error)
        self.assertTrue(token.requested)
        self.assert_stopped_inside_the_stage("cancelled.scene", lines)

    def test_ctrl_c_inside_a_stage_stops_the_solve(self):
        # The log is a builtin (list.append): it runs no Python code, so the interpreter cannot
        # act on the signal before a line is recorded (a Python callback would raise the
        # KeyboardInterrupt on entry, before recording the line that follows the stage).
        lines = []
        observed = threading.Event()

        def ctrl_c_once_the_stage_runs():
            # The line is appended while the solve holds the GIL; this thread runs again once
            # the solve has released it, inside the stage's work.
            while not any(line.startswith("done: observations") for line in list(lines)):
                if observed.wait(0.001):
                    return
            os.kill(os.getpid(), signal.SIGINT)

        watcher = threading.Thread(target=ctrl_c_once_the_stage_runs)
        watcher.start()
        try:
            with self.assertRaises(KeyboardInterrupt):
                rouen.solve(self.session_dir, os.path.join(self.tmp.name, "ctrl-c.scene"),
                            holdout_slots=[HELD_OUT], quick=True,
                            work=os.path.join(self.dir, "work"), log=lines.append)
        finally:
            observed.set()
            watcher.join()
        self.assert_stopped_inside_the_stage("ctrl-c.scene", lines)


class ReadImageTest(unittest.TestCase):
    def test_missing_file_names_it(self):
        with self.assertRaisesRegex(rouen.Error, "missing.exr"):
            rouen.read_image("/nonexistent/missing.exr")


if __name__ == "__main__":
    unittest.main()
