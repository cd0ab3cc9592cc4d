"""`blendsim-ray batch SCENES... --out DIR`: one `blendsim bake` per scene as a Ray task.

The driver lists each scene's inputs (`blendsim inputs`), packs them, and submits a task per
scene; a finished task sends its output folder back, and the driver commits it into
DIR/NAME with `blendsim commit`: the same staged, locked, one-step replace as a local bake.
At the end `blendsim report --batch` writes DIR/summary.md and DIR/summary.csv, as
`make batch` does. Ctrl-C cancels the tasks and leaves every folder as it was or complete.
"""

import argparse
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections import deque

from blendsim_ray import pack
from blendsim_ray.progress import Progress

EXIT_INTERRUPTED = 130


def parse_bytes(text):
    """A --max-memory amount in bytes (K, M, G, T: powers of 1024; KB, MB, GB, TB: of 1000)."""
    units = {"": 1, "B": 1, "K": 1024, "KIB": 1024, "M": 1024**2, "MIB": 1024**2, "G": 1024**3, "GIB": 1024**3,
             "T": 1024**4, "TIB": 1024**4, "KB": 1e3, "MB": 1e6, "GB": 1e9, "TB": 1e12}
    t = text.strip()
    number = t.rstrip("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ")
    unit = t[len(number):].upper()
    try:
        value = float(number) * units[unit]
    except (KeyError, ValueError):
        raise argparse.ArgumentTypeError(f"{text!r} is not an amount of memory: give e.g. 4G or 512MB") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive amount of memory: give e.g. 4G or 512MB")
    return int(value)


def find_blendsim(given):
    for candidate in [given, os.environ.get("BLENDSIM"), shutil.which("blendsim"), "target/release/blendsim"]:
        if candidate and os.path.isfile(candidate) and os.access(candidate, os.X_OK):
            return os.path.abspath(candidate)
    sys.exit("error: the blendsim binary was not found (fix: give --blendsim PATH, set BLENDSIM, put it on PATH, or run `make build`)")


def arguments(argv):
    parser = argparse.ArgumentParser(prog="blendsim-ray", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    b = sub.add_parser("batch", help="bake scenes on a Ray cluster into DIR/NAME, then DIR/summary.md and .csv")
    b.add_argument("scenes", nargs="+", metavar="SCENE", help="scene files (TOML); each bakes into DIR/<its file stem>")
    b.add_argument("-o", "--out", required=True, metavar="DIR", help="output folder (DIR/NAME per scene, DIR/summary.*)")
    b.add_argument("--address", default=os.environ.get("RAY_ADDRESS"),
                   help="the cluster's address (host:port of the head); default: RAY_ADDRESS, else the cluster this machine runs, else a Ray started for this batch")
    b.add_argument("--blendsim", metavar="PATH", help="the binary shipped to the workers (default: BLENDSIM, PATH, target/release/blendsim)")
    b.add_argument("--no-strip", action="store_true",
                   help="ship the binary as it is (by default a copy without debug symbols, made with `strip`, is shipped: a sixth of the bytes)")
    b.add_argument("--cpus-per-task", type=float, default=1.0, help="CPUs each bake reserves and its solver threads (default 1)")
    b.add_argument("--max-memory", type=parse_bytes, metavar="BYTES",
                   help="memory each bake reserves from Ray and may use (e.g. 4G); default: its node's memory over its CPUs, times --cpus-per-task")
    b.add_argument("--max-time", metavar="SECONDS", help="each bake's --max-time (e.g. 600, 10m)")
    b.add_argument("--max-retries", type=int, default=3, help="runs of a task again after its worker or node is lost (default 3)")
    b.add_argument("--strict", action="store_true", help="each bake's --strict: a bake with warnings fails")
    b.add_argument("--in-flight", type=int, metavar="N", help="tasks submitted at once (default: twice the cluster's CPUs); bounds the driver's memory")
    b.add_argument("--json", action="store_true", help="one JSON line per scene on stdout (status, node, error, seconds)")
    b.add_argument("-q", "--quiet", action="store_true", help="no progress bar (failures and the summary are still printed)")
    return parser.parse_args(argv)


class Interrupt:
    """SIGINT/SIGTERM set a flag that the driver's loop reads between steps: a commit in
    progress always finishes (it is atomic either way), and the tasks are then cancelled."""

    def __init__(self):
        self.signal = None
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self.handle)

    def handle(self, signum, _frame):
        self.signal = signum


def shipped_binary(blendsim, strip):
    """The bytes of the binary the workers run: without its debug symbols when `strip` is
    on the PATH (the release profile keeps them: 77 MB against 12 MB), else as it is."""
    if strip and shutil.which("strip"):
        with tempfile.TemporaryDirectory() as tmp:
            stripped = os.path.join(tmp, "blendsim")
            done = subprocess.run(["strip", "-o", stripped, blendsim], capture_output=True, text=True)
            if done.returncode == 0:
                with open(stripped, "rb") as f:
                    return f.read()
            reason = f"`strip` failed: {one_line(done.stderr)}"
    elif strip:
        reason = "`strip` is not on the PATH (binutils)"
    with open(blendsim, "rb") as f:
        data = f.read()
    if strip:
        # Correct either way, only more bytes to every node: a note, not a warning.
        print(f"blendsim-ray: note: {reason}; the workers get the binary as built "
              f"({len(data) / 1e6:.0f} MB) (fix: install binutils, or pass --no-strip)", file=sys.stderr)
    return data


def list_inputs(blendsim, scenes):
    """{scene: (inputs, error)} from `blendsim inputs` (one process for every scene)."""
    out = subprocess.run([blendsim, "inputs", *scenes], capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"error: {blendsim} inputs failed: {out.stderr.strip()} (fix: use the blendsim binary of this checkout: make build)")
    found = {}
    for line in out.stdout.splitlines():
        entry = json.loads(line)
        found[entry["scene"]] = (entry.get("inputs"), entry.get("error"))
    return found


def main(argv=None):
    try:
        return batch(arguments(sys.argv[1:] if argv is None else argv))
    except KeyboardInterrupt:
        # Before the tasks were submitted (listing the inputs, connecting): nothing written.
        print("blendsim-ray: interrupted before any task ran; nothing written", file=sys.stderr)
        return EXIT_INTERRUPTED


def batch(args):
    start = time.time()
    blendsim = find_blendsim(args.blendsim)
    out_dir = args.out.rstrip("/") or "/"
    names = {}
    for scene in args.scenes:
        name = os.path.splitext(os.path.basename(scene))[0]
        if name in names:
            sys.exit(f"error: {scene} and {names[name]} both bake into {os.path.join(out_dir, name)} "
                     "(fix: bake them in two batches into two --out folders, or rename one scene file)")
        names[name] = scene
    listed = list_inputs(blendsim, args.scenes)

    # Ray prints cluster events (a node marked dead) on stdout: they go to stderr, and stdout
    # holds only the --json lines.
    stdout = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)
    sys.stdout = sys.stderr

    import ray

    connecting = time.time()
    # The driver's own package goes to the workers with the job (Ray's py_modules): a node
    # needs Ray and Python, not this package.
    package = os.path.dirname(os.path.abspath(pack.__file__))
    ray.init(address=args.address, logging_level="ERROR", log_to_driver=False, configure_logging=True,
             runtime_env={"py_modules": [package]})
    connect_seconds = time.time() - connecting
    from blendsim_ray import worker

    # After ray.init, which may install handlers of its own.
    interrupt = Interrupt()

    binary = shipped_binary(blendsim, strip=not args.no_strip)
    sha = hashlib.sha256(binary).hexdigest()
    binary_ref = ray.put(binary)
    del binary
    cluster_cpus = int(ray.cluster_resources().get("CPU", 1))
    window = args.in_flight or max(2, 2 * cluster_cpus)
    remote = ray.remote(worker.bake)
    options = {"num_cpus": args.cpus_per_task, "max_retries": args.max_retries, "retry_exceptions": False}
    if args.max_memory:
        options["memory"] = args.max_memory

    progress = Progress(len(args.scenes), quiet=args.quiet, slots=max(1, int(cluster_cpus / args.cpus_per_task)))
    failures, records = [], []
    os.makedirs(out_dir, exist_ok=True)
    incoming = tempfile.mkdtemp(prefix=".blendsim-ray-incoming-", dir=out_dir)

    def fail(scene, reason, ran=True, **record):
        failures.append((scene, reason))
        records.append({"scene": scene, "status": "failed", "error": reason, **record})
        progress.failed(f"blendsim-ray: failed {scene}: {reason}", ran)

    cwd = os.getcwd()
    todo = deque()
    for scene in args.scenes:
        inputs, error = listed.get(scene, (None, "blendsim inputs did not list it"))
        if error:
            fail(scene, error, ran=False)
        else:
            todo.append(scene)
    in_flight = {}
    try:
        while (todo or in_flight) and interrupt.signal is None:
            while todo and len(in_flight) < window:
                scene = todo.popleft()
                name = os.path.splitext(os.path.basename(scene))[0]
                try:
                    data, job_cwd, scene_arg = pack.pack_inputs(scene, listed[scene][0], cwd)
                except OSError as e:
                    # Moved or made unreadable since it was listed.
                    fail(scene, f"{e.filename}: cannot be read to send it to the cluster: {e.strerror} (fix: check the file and run again)", ran=False)
                    continue
                job = {"name": name, "sha": sha, "cwd": job_cwd, "scene": scene_arg, "inputs": data,
                       "cpus": args.cpus_per_task, "max_time": args.max_time, "max_memory": args.max_memory, "strict": args.strict}
                in_flight[remote.options(**options).remote(job, [binary_ref])] = (scene, name, len(data), time.time())
            progress.update(running=len(in_flight))
            ready, _ = ray.wait(list(in_flight), num_returns=1, timeout=0.2)
            for ref in ready:
                scene, name, sent, submitted = in_flight.pop(ref)
                try:
                    result = ray.get(ref)
                except ray.exceptions.TaskCancelledError:
                    fail(scene, "cancelled")
                    continue
                except ray.exceptions.RayTaskError as e:
                    fail(scene, f"the task raised {type(e.cause).__name__}: {one_line(str(e.cause))}")
                    continue
                except ray.exceptions.RayError as e:
                    fail(scene, f"its worker or node was lost {args.max_retries + 1} times: {type(e).__name__}: {one_line(str(e))}")
                    continue
                record = {"node": result["node"], "worker_pid": result["pid"], "sent_bytes": sent, "seconds": time.time() - submitted, "times": result.get("times")}
                if result.get("error"):
                    fail(scene, result["error"], **record)
                    continue
                record["received_bytes"] = len(result["tar"])
                committing = time.time()
                error = commit(blendsim, result, os.path.join(incoming, name), os.path.join(out_dir, name))
                record["commit_seconds"] = time.time() - committing
                if error:
                    fail(scene, error, **record)
                else:
                    records.append({"scene": scene, "status": "ok", "out": os.path.join(out_dir, name), **record})
                    progress.done()
            progress.update(running=len(in_flight))
        if interrupt.signal is not None:
            cancel(ray, in_flight)
            progress.finish()
            print(f"blendsim-ray: interrupted: {len(in_flight)} running tasks cancelled, {len(todo)} not started; "
                  f"{progress.count_done} scenes committed; no summary written", file=sys.stderr)
            return EXIT_INTERRUPTED
    finally:
        shutil.rmtree(incoming, ignore_errors=True)
    progress.finish()
    summary = summarize(blendsim, out_dir)
    if args.json:
        for record in records:
            print(json.dumps(record), file=stdout)
        print(json.dumps({"batch": out_dir, "scenes": len(args.scenes), "failed": len(failures), "connect_seconds": connect_seconds,
                          "seconds": time.time() - start}), file=stdout)
        stdout.flush()
    seconds = time.time() - start
    baked = len(args.scenes) - len(failures)
    where = f"; summary: {out_dir}/summary.md, {out_dir}/summary.csv" if summary else ""
    if failures:
        print(f"blendsim-ray: {baked} of {len(args.scenes)} scenes baked into {out_dir} in {seconds:.1f} s{where}; {len(failures)} failed:", file=sys.stderr)
        for scene, reason in failures:
            print(f"  {scene}: {reason}", file=sys.stderr)
        return 1
    print(f"blendsim-ray: {baked} scenes baked into {out_dir} in {seconds:.1f} s{where}", file=sys.stderr)
    return 0


def one_line(text):
    """The first line of a message, without terminal colours."""
    text = re.sub(r"\x1b\[[0-9;]*m", "", text).strip()
    return text.splitlines()[0] if text else "(no message)"


def commit(blendsim, result, staged, target):
    """Unpack a worker's folder and commit it into `target` with `blendsim commit`; the error
    line, or None. The commit runs in a session of its own: a Ctrl-C at the terminal reaches
    the driver, which lets the commit finish."""
    try:
        pack.unpack(result["tar"], staged)
        done = subprocess.run([blendsim, "commit", staged, "--out", target, "--quiet"], capture_output=True, text=True,
                              start_new_session=True)
        if done.returncode != 0:
            lines = [l for l in done.stderr.splitlines() if l.strip()]
            return lines[-1].removeprefix("error: ") if lines else f"blendsim commit exited with {done.returncode}"
        return None
    finally:
        shutil.rmtree(staged, ignore_errors=True)


def cancel(ray, in_flight, grace=10.0):
    """Cancel the running tasks (KeyboardInterrupt in each: its bake is killed, its scratch
    removed) and wait for them to end, then force what is left."""
    refs = list(in_flight)
    for ref in refs:
        ray.cancel(ref, force=False)
    deadline = time.time() + grace
    remaining = refs
    while remaining and time.time() < deadline:
        _, remaining = ray.wait(remaining, num_returns=len(remaining), timeout=0.5)
    for ref in remaining:
        try:
            ray.cancel(ref, force=True)
        except Exception:
            pass


def summarize(blendsim, out_dir):
    """`blendsim report --batch` over every DIR/*/report.json, as `make batch` runs it."""
    baked = sorted(os.path.join(out_dir, e) + "/" for e in os.listdir(out_dir)
                   if not e.startswith(".") and os.path.isfile(os.path.join(out_dir, e, "report.json")))
    if not baked:
        return False
    done = subprocess.run([blendsim, "report", "--batch", *baked, "-o", out_dir, "--quiet"], capture_output=True, text=True)
    if done.returncode != 0:
        print(f"blendsim-ray: the summary failed: {done.stderr.strip()}", file=sys.stderr)
        return False
    return True
