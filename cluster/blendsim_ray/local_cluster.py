"""A throwaway Ray cluster on this machine: a head and N more nodes, each a `ray start --block`
process in a process group of its own, on free ports and under a temp dir of their own.

`ray stop` would stop every Ray process of the machine (a user's cluster, another test run's);
this stops only the process groups it started. The tests and the benchmark use it:

    with LocalCluster(nodes=2) as cluster:
        subprocess.run(["blendsim-ray", "batch", ..., "--address", cluster.address])
"""

import atexit
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time

# Node death is noticed within about 1.5 s instead of the default 15 s (the kill test waits
# for it); the head takes it for the whole cluster.
SYSTEM_CONFIG = '{"health_check_period_ms": 500, "health_check_failure_threshold": 3, "health_check_initial_delay_ms": 500}'


def free_ports(count):
    """`count` distinct TCP ports free now (bound to port 0 together, then released)."""
    socks = []
    try:
        for _ in range(count):
            s = socket.socket()
            s.bind(("127.0.0.1", 0))
            socks.append(s)
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


def ray_executable():
    return os.path.join(os.path.dirname(sys.executable), "ray")


def descendants(pid):
    """`pid` and every process below it (Ray's workers run in process groups of their own, so
    the tree is walked, not the group)."""
    children = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    # The command name may hold spaces: the fields after its closing parenthesis.
                    ppid = int(f.read().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(entry))
    found, todo = [], [pid]
    while todo:
        p = todo.pop()
        found.append(p)
        todo.extend(children.get(p, []))
    return found


class Node:
    def __init__(self, process, log):
        self.process = process
        self.log = log

    def kill(self, sig=signal.SIGKILL):
        """Signal every process of the node (ray start, raylet, workers, their children)."""
        for pid in descendants(self.process.pid):
            try:
                os.kill(pid, sig)
            except ProcessLookupError:
                pass

    def stop(self):
        tree = descendants(self.process.pid)
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout=15)
            except subprocess.TimeoutExpired:
                pass
        for pid in tree + descendants(self.process.pid):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        self.process.wait()


class LocalCluster:
    def __init__(self, nodes=2, cpus_per_node=1, temp_dir=None, env=None):
        self.nodes_wanted = nodes
        self.cpus = cpus_per_node
        self.own_temp = temp_dir is None
        # Ray's socket paths must stay under 107 bytes: a short temp dir.
        self.temp_dir = temp_dir or tempfile.mkdtemp(prefix="bsray-", dir="/tmp")
        self.env = dict(os.environ, **(env or {}))
        # Workers stage their bakes under TMPDIR: the cluster's own folder.
        self.env["TMPDIR"] = os.path.join(self.temp_dir, "work")
        os.makedirs(self.env["TMPDIR"], exist_ok=True)
        self.env.setdefault("RAY_USAGE_STATS_ENABLED", "0")
        # A token of its own for every node, worker and driver of this cluster. Left to Ray, a
        # head turns token authentication on when ~/.ray/auth_token exists (a local `ray.init()`
        # writes one) while the other nodes do not, and they fail to join.
        token_path = os.path.join(self.temp_dir, "auth_token")
        with open(os.open(token_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600), "w") as f:
            f.write(secrets.token_hex(32))
        self.env.update(RAY_AUTH_MODE="token", RAY_AUTH_TOKEN_PATH=token_path)
        self.env.pop("RAY_AUTH_TOKEN", None)
        self.nodes = []
        self.address = None

    def _start_node(self, head):
        gcs, node_manager, object_manager, client, agent, agent_grpc, runtime_env, metrics = free_ports(8)
        low = free_ports(1)[0]
        args = [
            ray_executable(), "start", "--block", "--disable-usage-stats",
            "--num-cpus", str(self.cpus),
            "--node-ip-address", "127.0.0.1",
            "--node-manager-port", str(node_manager),
            "--object-manager-port", str(object_manager),
            "--dashboard-agent-listen-port", str(agent),
            "--dashboard-agent-grpc-port", str(agent_grpc),
            "--runtime-env-agent-port", str(runtime_env),
            "--metrics-export-port", str(metrics),
            # Worker ports: a small range near a free port (each worker takes one).
            "--min-worker-port", str(low), "--max-worker-port", str(min(low + 40, 65535)),
            "--object-store-memory", str(200 * 1024 * 1024),
        ]
        if head:
            args += ["--head", "--port", str(gcs),
                     "--include-dashboard=false", "--temp-dir", self.temp_dir,
                     "--system-config", SYSTEM_CONFIG]
            self.address = f"127.0.0.1:{gcs}"
        else:
            args += ["--address", self.address]
        log = open(os.path.join(self.temp_dir, f"node-{len(self.nodes)}.log"), "wb")
        process = subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT, env=self.env, start_new_session=True)
        node = Node(process, log)
        self.nodes.append(node)
        return node

    def _wait_for_nodes(self, count, timeout=60):
        import ray

        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for node in self.nodes:
                if node.process.poll() is not None:
                    # Its log's last lines: the temp dir goes with the failed cluster.
                    node.log.flush()
                    with open(node.log.name, "rb") as f:
                        tail = f.read().decode(errors="replace").strip().splitlines()[-15:]
                    raise RuntimeError(f"a ray node exited with {node.process.returncode}; the end of its log:\n" + "\n".join(tail))
            try:
                out = subprocess.run(
                    [sys.executable, "-c",
                     "import ray,sys; ray.init(address=sys.argv[1], logging_level='ERROR');"
                     "print(sum(1 for n in ray.nodes() if n['Alive']))", self.address],
                    capture_output=True, text=True, env=self.env, timeout=30)
                if out.returncode == 0 and int(out.stdout.strip().splitlines()[-1]) >= count:
                    return
            except (subprocess.TimeoutExpired, ValueError, IndexError):
                pass
            time.sleep(0.5)
        raise RuntimeError(f"the local ray cluster did not reach {count} nodes in {timeout} s (logs in {self.temp_dir})")

    def start(self):
        """Start the nodes and wait for them; on a failure, stop what was started (and its temp dir)."""
        try:
            self._start_node(head=True)
            for _ in range(self.nodes_wanted - 1):
                self._start_node(head=False)
            self._wait_for_nodes(self.nodes_wanted)
        except BaseException:
            self.stop()
            raise
        self._stop_on_exit()
        return self

    def _stop_on_exit(self):
        """The nodes run in sessions of their own, so nothing else ends them: stop them when this
        process exits without calling `stop` (a test module whose teardown never ran) or is
        told to end by SIGTERM or SIGHUP (an interrupted `make test`), then end as the signal
        asks."""
        atexit.register(self.stop)
        if threading.current_thread() is not threading.main_thread():
            return

        def stop_and_end(signum, _frame):
            self.stop()
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)

        for signum in (signal.SIGTERM, signal.SIGHUP):
            if signal.getsignal(signum) == signal.SIG_DFL:
                signal.signal(signum, stop_and_end)

    def stop(self):
        """Stop every node started here and remove the temp dir; a second call does nothing."""
        nodes, self.nodes = self.nodes, []
        for node in reversed(nodes):
            node.stop()
            node.log.close()
        if self.own_temp:
            shutil.rmtree(self.temp_dir, ignore_errors=True)

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()
