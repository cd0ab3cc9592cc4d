"""The Ray task: one `blendsim bake` in a scratch folder of the worker's node.

The binary arrives once per node through the object store and is cached by its SHA-256; the
scene's inputs arrive with the task; the finished output folder goes back as a tar. Nothing is
written where the driver's output lives: the driver commits the folder itself."""

import ctypes
import os
import shutil
import signal
import subprocess
import tempfile
import time

import ray

from blendsim_ray import pack


def cache_dir():
    """Per user, under the worker's TMPDIR (BLENDSIM_RAY_CACHE overrides)."""
    return os.environ.get("BLENDSIM_RAY_CACHE") or os.path.join(tempfile.gettempdir(), f"blendsim-ray-{os.getuid()}")


# A cached binary no task used for this long is removed when another one is cached: each
# rebuild ships a new one (12 MB), and a node would otherwise keep them all.
UNUSED_SECONDS = 24 * 3600


def ensure_binary(sha, binary_ref):
    """The blendsim binary of hash `sha` on this node, fetched from the object store once."""
    folder = os.path.join(cache_dir(), "bin", sha)
    path = os.path.join(folder, "blendsim")
    if os.path.isfile(path):
        os.utime(folder)  # in use: kept by the clean-up below
        return path
    data = ray.get(binary_ref)
    os.makedirs(folder, exist_ok=True)
    tmp = f"{path}.tmp-{os.getpid()}"
    with open(tmp, "wb") as f:
        f.write(data)
    os.chmod(tmp, 0o755)
    os.replace(tmp, path)
    remove_unused_binaries(os.path.dirname(folder), keep=sha)
    return path


def remove_unused_binaries(bin_dir, keep, now=None):
    """Remove the cached binaries (their SHA folders) that no task used for UNUSED_SECONDS."""
    now = time.time() if now is None else now
    for entry in os.listdir(bin_dir):
        folder = os.path.join(bin_dir, entry)
        try:
            if entry != keep and now - os.stat(folder).st_mtime > UNUSED_SECONDS:
                shutil.rmtree(folder)
        except OSError:
            pass  # removed by another task meanwhile


def _die_with_parent():
    # The bake is killed with its worker (a lost node, a forced cancel): no orphan bakes on.
    ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG


_node_share = {}


def memory_share(cpus):
    """This node's memory over its CPUs, times the task's CPUs: a task's fair share when
    the node runs one task per CPU."""
    if "bytes" not in _node_share:
        node_id = ray.get_runtime_context().get_node_id()
        node = next((n for n in ray.nodes() if n["NodeID"] == node_id), None)
        resources = node["Resources"] if node else {}
        memory, node_cpus = resources.get("memory"), resources.get("CPU")
        _node_share["bytes"] = int(memory / node_cpus) if memory and node_cpus else None
    share = _node_share["bytes"]
    return None if share is None else int(share * cpus)


def bake(job, binary):
    """Run one bake. `job`: name, sha, cwd (relative to the unpacked root), scene (relative to
    cwd), inputs (tar bytes), cpus, max_time, max_memory, strict. `binary`: [ObjectRef of the
    binary's bytes] (in a list, so that it is fetched only when the node lacks it)."""
    started = time.time()
    context = ray.get_runtime_context()
    result = {"name": job["name"], "node": context.get_node_id(), "pid": os.getpid()}
    os.makedirs(cache_dir(), exist_ok=True)
    scratch = tempfile.mkdtemp(prefix="task-", dir=cache_dir())
    process = None
    try:
        exe = ensure_binary(job["sha"], binary[0])
        root = os.path.join(scratch, "in")
        pack.unpack(job["inputs"], root)
        # The driver's working folder, where relative scene paths start (it may hold no input).
        cwd = os.path.join(root, job["cwd"])
        os.makedirs(cwd, exist_ok=True)
        out = os.path.join(scratch, "out", job["name"])
        cmd = [exe, "bake", job["scene"], "--out", out, "--quiet", "--json"]
        if job.get("max_time"):
            cmd += ["--max-time", str(job["max_time"])]
        memory = job.get("max_memory") or memory_share(job["cpus"])
        if memory:
            cmd += ["--max-memory", str(memory)]
        if job.get("strict"):
            cmd.append("--strict")
        env = dict(os.environ, RAYON_NUM_THREADS=str(max(1, int(job["cpus"]))))
        bake_start = time.time()
        process = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE,
                                   stderr=subprocess.PIPE, preexec_fn=_die_with_parent)
        stdout, stderr = process.communicate()
        bake_end = time.time()
        result.update(exit=process.returncode, stderr=stderr.decode(errors="replace")[-4000:])
        process = None
        line = _last_json(stdout)
        if result["exit"] == 0:
            result["tar"] = pack.pack_folder(out)
            result["warnings"] = line.get("warnings", []) if line else []
        elif result["exit"] < 0:
            result["error"] = f"the bake was killed by signal {-result['exit']}" + (" (out of memory?)" if result["exit"] == -signal.SIGKILL else "")
        elif line and line.get("error"):
            result["error"] = line["error"]
        elif line and line.get("status") == "refused":
            result["error"] = "--strict refused the bake's warnings: " + "; ".join(line.get("warnings", []))
        else:
            lines = [l for l in result["stderr"].splitlines() if l.strip()]
            result["error"] = lines[-1] if lines else f"the bake exited with {result['exit']}"
        result["times"] = {"task": time.time() - started, "bake": bake_end - bake_start,
                           "before_bake": bake_start - started, "after_bake": time.time() - bake_end}
        return result
    finally:
        if process is not None and process.poll() is None:
            process.kill()
            process.wait()
        shutil.rmtree(scratch, ignore_errors=True)


def _last_json(stdout):
    import json

    for line in reversed(stdout.decode(errors="replace").splitlines()):
        try:
            return json.loads(line)
        except ValueError:
            continue
    return None
