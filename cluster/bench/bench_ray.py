"""`make bench-ray`: the same batch through `make -j2 batch` and through blendsim-ray on a
local two-node Ray cluster (1 CPU each: the same 2 cores), and where a task's time goes.

Scenes: the paper's (those whose assets are beside the clone; spot left out by default, it
alone takes 40 s) and variations of the demo (stiffness and tet size), BENCH_RAY_SCENES in
all (default 21). Prints a markdown table; mind the load average printed with it."""

import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import time

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(REPO, "cluster"))
from blendsim_ray.local_cluster import LocalCluster, descendants  # noqa: E402


def children_cpu():
    """CPU seconds of the waited-for children of this process (make, the driver, and theirs)."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def sample_cluster_cpu(cluster, seen):
    """Record in `seen` the CPU ticks of every process of the cluster's nodes (raylet, GCS,
    workers, with the bakes each worker has waited for: its children's times). The bakes
    still running are left out: their time joins their worker's once it waits for them.
    Sampled while the batch runs, since a job's workers end with its driver."""
    for node in cluster.nodes:
        for pid in descendants(node.process.pid):
            try:
                with open(f"/proc/{pid}/stat") as f:
                    text = f.read()
            except OSError:
                continue
            name, fields = text.split("(", 1)[1].rsplit(")", 1)[0], text.rsplit(")", 1)[1].split()
            if name != "blendsim":
                seen[pid] = max(seen.get(pid, 0), sum(int(x) for x in fields[11:15]))  # utime, stime, cutime, cstime


def cluster_cpu(seen):
    return sum(seen.values()) / os.sysconf("SC_CLK_TCK")

BIN = os.path.join(REPO, "target", "release", "blendsim")
WORK = os.path.join(REPO, "build", "bench-ray")
SCENES = os.path.join(WORK, "scenes")
PAPER = os.environ.get("BENCH_RAY_PAPER", "stretch,twist,ball,dino").split(",")


def make_scenes(total):
    shutil.rmtree(WORK, ignore_errors=True)
    os.makedirs(SCENES)
    count = 0
    # The scenes folder is one level deeper than fixtures/paper: one more `..` to the assets.
    for name in PAPER:
        with open(os.path.join(REPO, "fixtures", "paper", name + ".toml")) as f:
            text = f.read().replace('"../../../shared/', '"../../../../shared/')
        if "shared/assets" in text and not os.path.isdir(os.path.join(REPO, "..", "shared", "assets", "paper")):
            print(f"note: {name} left out (../shared/assets is missing)", file=sys.stderr)
            continue
        with open(os.path.join(SCENES, f"paper-{name}.toml"), "w") as f:
            f.write(text)
        count += 1
    demo = os.path.join(REPO, "fixtures", "demo")
    for f in os.listdir(demo):
        if not f.endswith(".toml"):
            shutil.copy(os.path.join(demo, f), SCENES)
    with open(os.path.join(demo, "twist.toml")) as f:
        text = f.read()
    for i in range(total - count):
        volume = ["0.005", "0.003"][i % 2]
        varied = text.replace("stiffness = 70.0", f"stiffness = {50.0 + 5 * i}").replace("max_volume = 0.005", f"max_volume = {volume}")
        with open(os.path.join(SCENES, f"demo-{i:02d}.toml"), "w") as f:
            f.write(varied)
    return sorted(os.path.join("build", "bench-ray", "scenes", n) for n in os.listdir(SCENES) if n.endswith(".toml"))


def median(values):
    return statistics.median(values) if values else float("nan")


def main():
    total = int(os.environ.get("BENCH_RAY_SCENES", "21"))
    scenes = make_scenes(total)
    load = os.getloadavg()
    local = {}
    # As `make -j2 batch` runs (each bake's solver on every core), and with one solver thread
    # per bake, as the Ray tasks run (--cpus-per-task 1).
    local_cpu = {}
    for threads in ("", "1"):
        start, cpu = time.time(), children_cpu()
        env = dict(os.environ, RAYON_NUM_THREADS=threads) if threads else os.environ
        subprocess.run(["make", "-s", "-j2", "batch", f"SCENES={SCENES}", f"BATCH_OUT={WORK}/local{threads}"], cwd=REPO, check=True,
                       stdout=subprocess.DEVNULL, env=env)
        local[threads] = time.time() - start
        local_cpu[threads] = children_cpu() - cpu

    started = time.time()
    with LocalCluster(nodes=2, cpus_per_node=1) as cluster:
        cluster_start = time.time() - started
        time.sleep(2)  # the nodes settle: their start-up is not the batch's
        before, during = {}, {}
        sample_cluster_cpu(cluster, before)
        start, cpu = time.time(), children_cpu()
        run = subprocess.Popen([sys.executable, "-m", "blendsim_ray", "batch", *scenes, "--out", f"{WORK}/ray", "--address", cluster.address,
                                "--blendsim", BIN, "--json", "--quiet"], cwd=REPO, env=dict(cluster.env, PYTHONPATH=os.path.join(REPO, "cluster")),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        while run.poll() is None:
            sample_cluster_cpu(cluster, during)
            time.sleep(0.2)
        stdout, stderr = run.communicate()
        ray_seconds = time.time() - start
        ray_cpu = children_cpu() - cpu + cluster_cpu(during) - cluster_cpu({p: t for p, t in before.items() if p in during})
    if run.returncode != 0:
        sys.exit(f"blendsim-ray failed:\n{stderr}")
    lines = [json.loads(l) for l in stdout.splitlines()]
    records = [l for l in lines if "scene" in l]
    batch = next(l for l in lines if "batch" in l)
    bake = [r["times"]["bake"] for r in records]
    worker_extra = [r["times"]["task"] - r["times"]["bake"] for r in records]
    commit = [r["commit_seconds"] for r in records]
    sent = [r["sent_bytes"] for r in records]
    received = [r["received_bytes"] for r in records]
    n = len(records)
    print(f"load average at the start: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} (2 cores)")
    print()
    print(f"| {n} scenes | seconds |")
    print("|---|---:|")
    print(f"| local `make -j2 batch` (whole batch) | {local[''] :.1f} |")
    print(f"| local `RAYON_NUM_THREADS=1 make -j2 batch` (one solver thread per bake, as the tasks) | {local['1']:.1f} |")
    print(f"| blendsim-ray batch on 2 nodes x 1 CPU (whole batch, driver start to summary) | {ray_seconds:.1f} |")
    print(f"| of which ray.init (connect to the cluster) | {batch['connect_seconds']:.2f} |")
    print(f"| starting the local cluster (not in the batch time) | {cluster_start:.1f} |")
    print(f"| overhead per task from the batch times: (ray - local, 1 thread) / scenes x 2 slots | {(ray_seconds - local['1']) / n * 2:.3f} |")
    print()
    print(f"| {n} scenes: CPU seconds (user + system) | local, 1 thread | blendsim-ray (driver + both nodes) | extra per task |")
    print("|---|---:|---:|---:|")
    print(f"| whole batch | {local_cpu['1']:.1f} | {ray_cpu:.1f} | {(ray_cpu - local_cpu['1']) / n:.3f} |")
    print(f"| (local with every core per bake: {local_cpu['']:.1f}) | | | |")
    print()
    print("| per task (medians) | value |")
    print("|---|---:|")
    print(f"| the bake (blendsim bake on the worker) | {median(bake):.3f} s |")
    print(f"| on the worker around it (binary, unpack, pack, scratch) | {median(worker_extra):.4f} s |")
    print(f"| commit on the driver (unpack, blendsim commit) | {median(commit):.4f} s |")
    print(f"| inputs sent (tar) | {median(sent) / 1024:.0f} KB (max {max(sent) / 1024:.0f} KB) |")
    print(f"| outputs received (tar) | {median(received) / 1024:.0f} KB (max {max(received) / 1024:.0f} KB) |")
    print(f"| first task on a node also fetches the binary (stripped; {os.path.getsize(BIN) / 1e6:.0f} MB as built) | {stripped_size() / 1e6:.1f} MB |")
    print(f"| bake time, min / max | {min(bake):.2f} / {max(bake):.2f} s |")
    print(f"| summed over the batch: sent, received | {sum(sent) / 1e6:.2f} MB, {sum(received) / 1e6:.1f} MB |")


def stripped_size():
    from blendsim_ray.cli import shipped_binary

    return len(shipped_binary(BIN, strip=True))


if __name__ == "__main__":
    main()
