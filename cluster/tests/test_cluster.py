"""blendsim-ray on a local Ray cluster started here (a head and a worker node, 1 CPU each, on
ports and a temp dir of their own; stopped by process id, never by `ray stop`).

- the demo and the paper scenes give the same files as local bakes, and the same summary as
  `make batch`'s (report.json and report.md: the wall-clock fields aside, as in the Rust suite);
- a node killed in the middle of a bake: the task runs again on another node, every folder
  ends complete, the summary lists every scene once;
- a bad scene: its one-line error (the local bake's) in one failure line, the others complete;
- the driver interrupted (SIGINT): the running bakes end, no folder is half-written.

Ray (the version cluster/pyproject.toml pins), the binary and TetGen are required: a missing
one fails the run, CI or not. The paper scenes read ../shared/assets beside the clone: with
CI=true a missing asset fails the test; elsewhere those scenes are left out with a note. `python -m unittest discover -s
cluster/tests` from the repository (make test-ray)."""

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import unittest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(REPO, "cluster"))

from blendsim_ray.local_cluster import LocalCluster, descendants, ray_executable  # noqa: E402

BIN = os.environ.get("BLENDSIM", os.path.join(REPO, "target", "release", "blendsim"))
DRIVER = [sys.executable, "-m", "blendsim_ray"]
# Every paper scene (BLENDSIM_RAY_PAPER_SCENES=stretch,twist for fewer while working on the driver).
PAPER = os.environ.get("BLENDSIM_RAY_PAPER_SCENES", "stretch,twist,ball,dino,spot").split(",")
TIMINGS = ("seconds", "precompute_seconds", "iteration_seconds")

cluster = None


def require_tools():
    """Ray (the pinned version, in this Python), the binary and TetGen: a missing one fails the
    run, with CI=true or not (as the Rust suite's checkers): a test that passes by skipping its
    cluster proves nothing."""
    fix = "(fix: make deps-ray, then run the tests with build/ray-venv/bin/python: make test-ray)"
    try:
        import ray
    except ImportError:
        raise AssertionError(f"Ray is not installed in {sys.executable} {fix}") from None
    pinned = re.search(r'"ray==([^"]+)"', read_text(os.path.join(REPO, "cluster", "pyproject.toml"))).group(1)
    if ray.__version__ != pinned:
        raise AssertionError(f"Ray {ray.__version__} in {sys.executable}, the driver pins {pinned} {fix}")
    if not os.access(ray_executable(), os.X_OK):
        raise AssertionError(f"{ray_executable()} (Ray's command line, beside this Python) is missing {fix}")
    if not os.access(BIN, os.X_OK):
        raise AssertionError(f"the blendsim binary {BIN} is missing (fix: make build, or set BLENDSIM)")
    if not shutil.which(os.environ.get("BLENDSIM_TETGEN") or "tetgen"):
        raise AssertionError("TetGen is missing: `tetgen` is not on PATH nor BLENDSIM_TETGEN set (fix: make deps-tetgen)")


def setUpModule():
    global cluster
    require_tools()
    cluster = LocalCluster(nodes=2).start()


def tearDownModule():
    if cluster:
        cluster.stop()


def driver_env():
    # The driver imports this checkout's package; the workers get it from the driver (py_modules).
    return dict(cluster.env, PYTHONPATH=os.path.join(REPO, "cluster"))


def driver(args, cwd=REPO, **kwargs):
    return subprocess.run(DRIVER + ["batch", *args, "--address", cluster.address, "--blendsim", BIN],
                          cwd=cwd, env=driver_env(), capture_output=True, text=True, timeout=300, **kwargs)


def without_timings(report):
    solver = report["solver"]
    for key in TIMINGS:
        assert solver.pop(key, None) is not None, f"report.json solver.{key} is missing"
    split = solver.get("iteration_split")
    if isinstance(split, dict):
        split.pop("evaluation_seconds")
        split.pop("solve_seconds")
    return report


def without_column(table, sep, column):
    """The rows of a csv or markdown table without one column (found by its header)."""
    rows = [line.split(sep) for line in table.splitlines()]
    header = next(row for row in rows if column in [cell.strip() for cell in row])
    at = [cell.strip() for cell in header].index(column)
    return [row[:at] + row[at + 1:] if len(row) == len(header) else row for row in rows]


def assert_same_bake(test, local, remote):
    """Every file of two bake folders the same bytes (reports: the timings aside)."""
    names = sorted(os.listdir(local))
    test.assertEqual(sorted(os.listdir(remote)), names, remote)
    for name in names:
        a, b = os.path.join(local, name), os.path.join(remote, name)
        if name == "report.json":
            with open(a) as fa, open(b) as fb:
                test.assertEqual(without_timings(json.load(fa)), without_timings(json.load(fb)), b)
        elif name == "report.md":
            drop = lambda p: [l for l in read_text(p).splitlines() if not l.startswith("| time |")]  # noqa: E731
            test.assertEqual(drop(a), drop(b), b)
        elif name == "report.html":
            drop = lambda p: [l for l in read_text(p).splitlines() if not l.startswith("<tr><td>time</td>")]  # noqa: E731
            test.assertEqual(drop(a), drop(b), b)
        else:
            with open(a, "rb") as fa, open(b, "rb") as fb:
                test.assertTrue(fa.read() == fb.read(), f"{b} differs from the local bake's {a}")


def assert_complete(test, folder):
    """A committed bake: its manifest and every file the manifest lists, nothing else of ours."""
    with open(os.path.join(folder, ".blendsim-manifest.json")) as f:
        files = json.load(f)["files"]
    test.assertIn("report.json", files)
    test.assertEqual(sorted(os.listdir(folder)), sorted([".blendsim-manifest.json", *files]), folder)


def assert_nothing_half_written(test, out):
    """No staging folder, lock, temporary or unpacked incoming folder left in `out`."""
    leftovers = [e for e in os.listdir(out) if e.startswith(".") and e != ".blendsim-manifest.json"]
    test.assertEqual(leftovers, [], f"{out} holds leftovers")


def local_batch(scenes, out, cwd=REPO):
    """What `make batch` runs: a bake per scene into OUT/NAME, then the summary of OUT/*/."""
    for scene in scenes:
        name = os.path.splitext(os.path.basename(scene))[0]
        subprocess.run([BIN, "bake", scene, "-o", os.path.join(out, name), "--depfile", os.path.join(out, name + ".d"), "--quiet"],
                       cwd=cwd, check=True)
    baked = sorted(os.path.join(out, n) + "/" for n in os.listdir(os.path.join(cwd, out)) if os.path.isfile(os.path.join(cwd, out, n, "report.json")))
    subprocess.run([BIN, "report", "--batch", *baked, "-o", out, "--quiet"], cwd=cwd, check=True)


def paper_scenes():
    """fixtures/paper/NAME.toml for each of PAPER whose assets are present (CI=true: all must be)."""
    found = []
    for name in PAPER:
        scene = os.path.join("fixtures", "paper", name + ".toml")
        text = read_text(os.path.join(REPO, scene))
        missing = [p for p in re.findall(r'"([^"]*shared/assets/paper/[^"]*)"', text)
                   if not os.path.isfile(os.path.join(REPO, "fixtures", "paper", p))]
        if missing:
            if os.environ.get("CI") == "true":
                raise AssertionError(f"test asset {missing[0]} of {scene} is missing (required when CI=true): put the paper's assets in ../shared/assets/paper")
            print(f"skipped: {scene}: test asset {missing[0]} is missing (set CI=true to make this a failure)", file=sys.stderr)
            continue
        found.append(scene)
    return found


def demo_variations(folder, count, max_volume="0.005"):
    """`count` scenes in `folder`: the demo with other stiffnesses (and tet sizes)."""
    demo = os.path.join(REPO, "fixtures", "demo")
    for f in os.listdir(demo):
        shutil.copy(os.path.join(demo, f), folder)
    with open(os.path.join(demo, "twist.toml")) as f:
        text = f.read()
    scenes = []
    for i in range(count):
        varied = text.replace("stiffness = 70.0", f"stiffness = {60.0 + 5 * i}").replace("max_volume = 0.005", f"max_volume = {max_volume}")
        assert varied != text
        path = os.path.join(folder, f"var-{i:02d}.toml")
        with open(path, "w") as f:
            f.write(varied)
        scenes.append(path)
    return scenes


def read_text(path):
    with open(path) as f:
        return f.read()


def folder_bytes(folder):
    found = {}
    for name in os.listdir(folder):
        with open(os.path.join(folder, name), "rb") as f:
            found[name] = f.read()
    return found


def bakes_under(pid):
    """The `blendsim bake` processes below a process: {pid: its command line}."""
    found = {}
    for p in descendants(pid):
        try:
            with open(f"/proc/{p}/cmdline", "rb") as f:
                cmd = f.read().split(b"\0")
        except OSError:
            continue
        if len(cmd) > 2 and cmd[0].endswith(b"blendsim") and cmd[1] == b"bake":
            found[p] = [c.decode() for c in cmd if c]
    return found


def all_bakes():
    found = {}
    for node in cluster.nodes:
        found.update(bakes_under(node.process.pid))
    return found


class Cluster(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.mkdtemp(prefix="blendsim-ray-test-")

    def tearDown(self):
        shutil.rmtree(self.tmp, ignore_errors=True)

    def test_the_demo_and_the_paper_scenes_bake_the_same_files_as_locally(self):
        for scenes in (["fixtures/demo/twist.toml"], paper_scenes()):
            if not scenes:
                continue
            tag = os.path.basename(os.path.dirname(scenes[0]))
            local, remote = os.path.join(self.tmp, f"local-{tag}"), os.path.join(self.tmp, f"ray-{tag}")
            # The local bakes run while the cluster bakes (SPOT alone is 16 CPU seconds).
            run = subprocess.Popen(DRIVER + ["batch", *scenes, "--out", remote, "--address", cluster.address, "--blendsim", BIN],
                                   cwd=REPO, env=driver_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            try:
                local_batch(scenes, local)
                _, stderr = run.communicate(timeout=300)
            finally:
                if run.poll() is None:
                    run.kill()
            self.assertEqual(run.returncode, 0, stderr)
            for scene in scenes:
                name = os.path.splitext(os.path.basename(scene))[0]
                assert_same_bake(self, os.path.join(local, name), os.path.join(remote, name))
            # The summary is `make batch`'s, but for the folder names in its bake column.
            # The bakes' wall-clock seconds aside.
            for name, sep in (("summary.md", "|"), ("summary.csv", ",")):
                ours = read_text(os.path.join(remote, name)).replace(remote + "/", "OUT/")
                theirs = read_text(os.path.join(local, name)).replace(local + "/", "OUT/")
                self.assertEqual(without_column(ours, sep, "seconds"), without_column(theirs, sep, "seconds"), name)
            assert_nothing_half_written(self, remote)

    def test_a_bad_scene_fails_with_its_one_line_error_and_the_others_complete(self):
        scenes = demo_variations(self.tmp, 2)
        # A key with a vertex less than the others: the bake's own one-line error.
        with open(os.path.join(self.tmp, "prism_left.obj")) as f:
            lines = f.read().splitlines()
        drop = max(i for i, l in enumerate(lines) if l.startswith("v "))
        with open(os.path.join(self.tmp, "short.obj"), "w") as f:
            f.write("\n".join(l for i, l in enumerate(lines) if i != drop and not l.startswith("f ")) + "\n")
        # Relative paths, as a user gives them: the messages name them so on both sides.
        scenes = [os.path.relpath(s, REPO) for s in scenes]
        bad = os.path.relpath(os.path.join(self.tmp, "bad.toml"), REPO)
        with open(os.path.join(REPO, scenes[0])) as f:
            text = f.read().replace('"prism_left.obj"', '"short.obj"')
        with open(os.path.join(REPO, bad), "w") as f:
            f.write(text)
        local = subprocess.run([BIN, "bake", bad, "-o", os.path.join(self.tmp, "local-bad")], cwd=REPO, capture_output=True, text=True)
        self.assertEqual(local.returncode, 1)
        error = local.stderr.strip().splitlines()[-1].removeprefix("error: ")
        out = os.path.join(self.tmp, "out")
        run = driver([scenes[0], bad, scenes[1], "--out", out])
        self.assertEqual(run.returncode, 1, run.stderr)
        failed = [l for l in run.stderr.splitlines() if l.startswith("blendsim-ray: failed")]
        self.assertEqual(failed, [f"blendsim-ray: failed {bad}: {error}"], run.stderr)
        self.assertIn(f"  {bad}: {error}", run.stderr.splitlines(), "the closing summary names it again")
        self.assertFalse(os.path.exists(os.path.join(out, "bad")))
        for scene in scenes:
            assert_complete(self, os.path.join(out, os.path.splitext(os.path.basename(scene))[0]))
        summary = read_text(os.path.join(out, "summary.csv"))
        self.assertEqual(len(summary.strip().splitlines()), 1 + len(scenes), summary)
        assert_nothing_half_written(self, out)

    def test_a_node_killed_in_the_middle_of_a_bake_the_task_runs_again(self):
        extra = cluster._start_node(head=False)
        cluster._wait_for_nodes(len(cluster.nodes))
        scenes = demo_variations(self.tmp, 4, max_volume="0.001")
        out = os.path.join(self.tmp, "out")
        process = subprocess.Popen(DRIVER + ["batch", *scenes, "--out", out, "--address", cluster.address, "--blendsim", BIN, "--json"],
                                   cwd=REPO, env=driver_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            deadline = time.time() + 120
            while time.time() < deadline and not bakes_under(extra.process.pid) and process.poll() is None:
                time.sleep(0.02)
            victims = bakes_under(extra.process.pid)
            self.assertTrue(victims, "no bake ran on the extra node")
            killed_workers = set(descendants(extra.process.pid))
            extra.kill()
            stdout, stderr = process.communicate(timeout=240)
        finally:
            if process.poll() is None:
                process.kill()
            extra.stop()
            extra.log.close()
            cluster.nodes.remove(extra)
        self.assertEqual(process.returncode, 0, stderr)
        killed_scene = next(c for c in next(iter(victims.values())) if c.endswith(".toml"))
        records = {r["scene"]: r for r in map(json.loads, stdout.splitlines()) if "scene" in r}
        self.assertEqual(sorted(records), sorted(scenes))
        record = next(r for s, r in records.items() if os.path.basename(s) == os.path.basename(killed_scene))
        self.assertEqual(record["status"], "ok")
        self.assertNotIn(record["worker_pid"], killed_workers, "the killed bake ran again on a live node")
        for scene in scenes:
            assert_complete(self, os.path.join(out, os.path.splitext(os.path.basename(scene))[0]))
        rows = read_text(os.path.join(out, "summary.csv")).strip().splitlines()[1:]
        self.assertEqual(sorted(r.split(",")[0] for r in rows), sorted(os.path.join(out, f"var-{i:02d}") for i in range(4)))
        assert_nothing_half_written(self, out)

    def test_the_driver_interrupted_cancels_its_tasks_and_leaves_no_half_written_folder(self):
        scenes = demo_variations(self.tmp, 6, max_volume="0.001")
        out = os.path.join(self.tmp, "out")
        # An earlier bake in one of the folders: it stays whole (the old one or a new one).
        local_batch([scenes[5]], out)
        before = folder_bytes(os.path.join(out, "var-05"))
        os.remove(os.path.join(out, "summary.md"))
        process = subprocess.Popen(DRIVER + ["batch", *scenes, "--out", out, "--address", cluster.address, "--blendsim", BIN],
                                   cwd=REPO, env=driver_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            deadline = time.time() + 120
            while time.time() < deadline and not all_bakes() and process.poll() is None:
                time.sleep(0.02)
            self.assertTrue(all_bakes(), "no bake started")
            process.send_signal(signal.SIGINT)
            _, stderr = process.communicate(timeout=60)
        finally:
            if process.poll() is None:
                process.kill()
        self.assertEqual(process.returncode, 130, stderr)
        self.assertIn("interrupted", stderr)
        # The running bakes end with their tasks (the cancel kills them).
        deadline = time.time() + 20
        while all_bakes() and time.time() < deadline:
            time.sleep(0.1)
        self.assertEqual(all_bakes(), {}, "bakes still running after the driver was interrupted")
        for name in os.listdir(out):
            path = os.path.join(out, name)
            if os.path.isdir(path):
                assert_complete(self, path)
        after = folder_bytes(os.path.join(out, "var-05"))
        self.assertEqual(sorted(after), sorted(before))
        self.assertFalse(os.path.exists(os.path.join(out, "summary.md")), "no summary after an interrupt")
        assert_nothing_half_written(self, out)


if __name__ == "__main__":
    unittest.main()
