"""Dask: a real LocalCluster of 2 worker processes gives byte-identical files to the serial
run, also when a worker process is killed mid-run; scheduler addresses; lazy import."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from functools import partial
from pathlib import Path

import numpy as np
import pytest

import depthnormals as dn
from depthnormals import cluster, jobs

distributed = pytest.importorskip("distributed")

K = (60.0, 62.0, 31.5, 23.5)


def _frame(i: int, shape=(48, 64)) -> np.ndarray:
    rng = np.random.default_rng(i)
    v, u = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    z = (2.0 + 0.05 * i) / (1.0 + 0.003 * (i % 5 + 1) * (u - K[2]) / K[0] - 0.002 * (v - K[3]) / K[1])
    z += rng.normal(0.0, 0.002, z.shape)
    z[rng.random(z.shape) < 0.03] = 0.0
    return z.astype(np.float32)


@pytest.fixture(scope="module")
def client():
    """A LocalCluster of 2 single-threaded worker processes (nannies restart killed ones)."""
    with cluster.local_cluster(2, threads=1) as lc, distributed.Client(lc) as cl:
        yield cl


@pytest.fixture(scope="module")
def frames(tmp_path_factory):
    folder = tmp_path_factory.mktemp("frames")
    for i in range(24):
        np.save(folder / f"{i:02d}.npy", _frame(i))
    return folder


def _files(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` by relative path, but the temporary files of atomic writes
    (hidden ``.*.tmp``), which a worker killed mid-write leaves behind, and the run's manifest
    and inputs log (its lines in the order the frames finished)."""
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and not (p.name.startswith(".") and p.name.endswith(".tmp"))
            and p.name not in (jobs.MANIFEST, jobs.INPUTS_LOG)}


def test_estimate_on_cluster_equals_serial(client, frames, tmp_path):
    serial = jobs.run_estimate([frames], tmp_path / "serial", method="3f2n+", K=K)
    dask = jobs.run_estimate([frames], tmp_path / "dask", method="3f2n+", K=K, scheduler=client, batch_size=5)
    assert (serial.planned, serial.written, dask.planned, dask.written) == (24, 24, 24, 24)
    a, b = _files(tmp_path / "serial"), _files(tmp_path / "dask")
    assert len(a) == 24 and a == b
    # and they are the library's numbers
    assert np.load(tmp_path / "dask" / "07.npy").tobytes() == \
        dn.estimate_normals(_frame(7), K, method="3f2n+").tobytes()
    # resumable on the cluster too: nothing left to do
    again = jobs.run_estimate([frames], tmp_path / "dask", method="3f2n+", K=K, scheduler=client)
    assert (again.written, again.skipped) == (0, 24)


def test_worker_killed_mid_run(client, frames, tmp_path):
    """os.kill of one worker process after the first batch completes: Dask re-runs its
    tasks on the other worker (and the restarted one); the files are the serial run's."""
    jobs.run_estimate([frames], tmp_path / "serial", method="sda-sne", K=K)
    pids = client.run(os.getpid)
    assert len(pids) == 2
    victim = sorted(pids.values())[0]
    killed = []

    def on_done(job, _):
        if not killed:
            os.kill(victim, signal.SIGKILL)
            killed.append(job)

    todo = list(jobs.plan_estimate([frames], tmp_path / "dask", K=K))
    func = partial(jobs.estimate_job, settings=jobs.EstimateSettings("sda-sne"))
    done = cluster.map_batches(func, todo, client=client, batch_size=2, on_done=on_done)
    assert killed and len(done) == 24
    assert _files(tmp_path / "serial") == _files(tmp_path / "dask")
    client.wait_for_workers(2, timeout=60)
    assert victim not in client.run(os.getpid).values()  # it really died (and was replaced)


def test_synth_on_cluster_equals_serial(client, tmp_path):
    from depthnormals.synth import generate

    kw = dict(indoor=1, outdoor=1, views=3, size=(36, 48), K=(27.0, 27.0, 23.5, 17.5),
              noise=("gaussian:sigma=0.01",), progress=False)
    s = generate(tmp_path / "serial", **kw)
    d = generate(tmp_path / "dask", scheduler=client.scheduler.address, batch_size=2, **kw)
    assert (s.written, d.written, d.skipped) == (6, 6, 0)
    a, b = _files(tmp_path / "serial"), _files(tmp_path / "dask")
    assert len(a) == 1 + 2 * (1 + 4 * 3) and a == b
    again = generate(tmp_path / "dask", scheduler=client.scheduler.address, **kw)
    assert (again.written, again.skipped) == (0, 6)


def test_cli_scheduler_local(frames, tmp_path, capsys):
    from depthnormals.cli import main

    (tmp_path / "k.json").write_text('{"fx": 60, "fy": 62, "cx": 31.5, "cy": 23.5}')
    files = [str(frames / f"{i:02d}.npy") for i in range(4)]
    assert main(["estimate", *files, "-K", str(tmp_path / "k.json"), "-o", str(tmp_path / "o"),
                 "-m", "d2nt", "--scheduler", "local:1", "-q"]) == 0
    assert "4 frames by d2nt (4 computed, 0 done before)" in capsys.readouterr().out
    assert np.load(tmp_path / "o" / "02.npy").tobytes() == \
        dn.estimate_normals(_frame(2), K, method="d2nt").tobytes()


@pytest.mark.parametrize("text, address, workers", [
    ("local", None, None), ("local:3", None, 3), (" tcp://10.0.0.5:8786 ", "tcp://10.0.0.5:8786", None),
    ("tls://host:1", "tls://host:1", None)])
def test_parse_scheduler(text, address, workers):
    spec = cluster.parse_scheduler(text)
    assert (spec.address, spec.workers, spec.local) == (address, workers, address is None)


@pytest.mark.parametrize("text", ["", "local:0", "local:x", "10.0.0.5:8786", "http://x:1"])
def test_parse_scheduler_rejects(text):
    with pytest.raises(ValueError, match="local:N"):
        cluster.parse_scheduler(text)


def test_map_batches_locally_and_bad_batch():
    assert sorted(cluster.map_batches(abs, [-3, 1, -2])) == [1, 2, 3]
    with pytest.raises(ValueError, match="batch_size"):
        cluster.map_batches(abs, [1], batch_size=0)


def test_import_stays_light():
    code = ("import sys, depthnormals, depthnormals.cluster, depthnormals.jobs, depthnormals.batch; "
            "print(any(m == 'dask' or m.startswith(('dask.', 'distributed')) for m in sys.modules))")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1] / "src")}
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         timeout=120, check=True)
    assert res.stdout.strip() == "False"


def _faults_per_frame(n: int) -> float:
    import resource

    z = np.repeat(np.repeat(_frame(n), 10, axis=0), 10, axis=1)  # 480 x 640, noisy, holes
    for _ in range(2):  # warm: compiled, heap grown (the second frame still grows it a little:
        dn.estimate_normals(z, K, method="3f2n+")  # 150-300 faults, then 0-1 a frame)
    r0 = resource.getrusage(resource.RUSAGE_THREAD).ru_minflt
    for _ in range(n):
        dn.estimate_normals(z, K, method="3f2n+")
    return (resource.getrusage(resource.RUSAGE_THREAD).ru_minflt - r0) / n


def test_workers_reuse_their_heap(client):
    """Our worker processes keep frame-sized temporaries on the heap (WORKER_MALLOC_ENV): with
    Dask's default malloc setting each 640x480 3f2n+ frame page-faults again (755 times here)."""
    envs = client.run(lambda: os.environ.get("MALLOC_MMAP_THRESHOLD_"))
    assert set(envs.values()) == {cluster.WORKER_MALLOC_ENV["MALLOC_MMAP_THRESHOLD_"]}
    assert client.submit(_faults_per_frame, 3, pure=False).result() < 100  # 0 measured; 755 with the default


def _without_ms(obj):
    """A JSON tree without its timings (keys containing 'ms')."""
    if isinstance(obj, dict):
        return {k: _without_ms(v) for k, v in obj.items() if "ms" not in k}
    if isinstance(obj, list):
        return [_without_ms(v) for v in obj]
    return obj


def test_evaluate_on_cluster_equals_serial(client, tmp_path, capsys):
    import csv
    import json

    from depthnormals.cli import main
    from depthnormals.synth import generate

    generate(tmp_path / "ds", indoor=1, outdoor=1, views=2, size=(36, 48), K=(27.0, 27.0, 23.5, 17.5),
             noise=("gaussian:sigma=0.01",), progress=False)
    base = ["evaluate", str(tmp_path / "ds"), "-m", "3f2n,d2nt+", "--figures", "0", "-q"]
    assert main([*base, "-o", str(tmp_path / "serial")]) == 0
    dask = [*base, "-o", str(tmp_path / "dask"), "--scheduler", client.scheduler.address, "--batch-size", "3"]
    assert main(dask) == 0
    out = capsys.readouterr().out
    assert "16 rows (16 computed, 0 reused" in out  # serial run
    assert "16 rows (0 computed, 16 reused" in out  # the Dask run: every part done by the workers

    def rows(name):
        with (tmp_path / name / "results.csv").open() as fh:
            return [{k: v for k, v in r.items() if k != "ms"} for r in csv.DictReader(fh)]

    assert len(rows("serial")) == 16 and rows("serial") == rows("dask")
    assert _without_ms(json.loads((tmp_path / "serial" / "summary.json").read_text())) == \
        _without_ms(json.loads((tmp_path / "dask" / "summary.json").read_text()))
    assert main(dask) == 0  # resumed: nothing left for the workers
    assert "16 rows (0 computed, 16 reused" in capsys.readouterr().out


def test_workers_of_another_build_are_refused_before_any_work(client, frames, tmp_path, monkeypatch):
    """Workers left on another build of the library (here: this process's code digest
    changed, the workers' not) would write outputs that pass for this run's (the manifest
    records this process's digest): refused before any task, nothing written. Before: the run
    went ahead."""
    from depthnormals import _fingerprint

    here = _fingerprint.code_fingerprint()
    assert client.run(cluster._worker_code) == {w: here for w in client.scheduler_info()["workers"]}
    monkeypatch.setattr(_fingerprint, "code_fingerprint", lambda: "0" * 24)
    with pytest.raises(cluster.WorkerCodeMismatch, match="another build of depthnormals"):
        jobs.run_estimate([frames], tmp_path / "out", method="3f2n", K=K, scheduler=client)
    assert not list(tmp_path.rglob("*.npy"))
    monkeypatch.undo()
    assert jobs.run_estimate([frames], tmp_path / "out", method="3f2n", K=K, scheduler=client).written == 24


def test_a_task_checks_its_workers_build_before_it_starts(tmp_path):
    """A worker that joined after the cluster was checked: its first task refuses to run."""
    calls = []
    with pytest.raises(cluster.WorkerCodeMismatch, match="nothing was computed"):
        cluster._run_batch(calls.append, [1, 2], "0" * 24)
    assert calls == []
    assert cluster._run_batch(calls.append, [1, 2], cluster._worker_code()) == [None, None]
    assert calls == [1, 2]
