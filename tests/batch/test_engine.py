import os
from pathlib import Path

import numpy as np
import pytest

from fpm_sim.batch.engine import EngineError, EngineOptions, chunk_size, run_chunks, split
from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.kinematics import Pose


def _square_and_log(item: int, *, log_dir: str) -> int:
    """Squares ``item`` and leaves a file per call (to count calls across resumes)."""
    Path(log_dir, f"{item}-{os.getpid()}-{len(os.listdir(log_dir))}").touch()
    return item * item


def test_chunks_split_and_size():
    assert split(list(range(5)), 2) == [[0, 1], [2, 3], [4]]
    assert chunk_size(10, 2) == 16  # floor: a chunk holds at least MIN_CHUNK items
    assert chunk_size(100_000, 2) == 512  # ceiling
    assert chunk_size(2000, 2) == 250  # four chunks per worker in between


def test_resume_recomputes_only_the_missing_chunks(tmp_path):
    log, store = tmp_path / "log", tmp_path / "store"
    log.mkdir()
    opts = EngineOptions(scheduler="serial", store=store)
    assert run_chunks(_square_and_log, [1, 2, 3, 4], kwargs={"log_dir": str(log)}, options=opts) == [1, 4, 9, 16]
    assert len(list(log.iterdir())) == 4
    assert len(list(store.glob("*.pkl"))) == 4
    # a killed run: two chunks never written
    for path in sorted(store.glob("*.pkl"))[:2]:
        path.unlink()
    resumed = EngineOptions(scheduler="serial", store=store, resume=True)
    assert run_chunks(_square_and_log, [1, 2, 3, 4], kwargs={"log_dir": str(log)}, options=resumed) == [1, 4, 9, 16]
    assert len(list(log.iterdir())) == 6  # only the two missing chunks ran again
    # without --resume the store is cleared and everything runs
    run_chunks(_square_and_log, [1, 2, 3, 4], kwargs={"log_dir": str(log)}, options=opts)
    assert len(list(log.iterdir())) == 10


def test_bad_engine_options_are_named():
    with pytest.raises(EngineError, match="scheduler"):
        EngineOptions(scheduler="somewhere")
    with pytest.raises(EngineError, match="workers"):
        EngineOptions(workers=0)
    with pytest.raises(EngineError, match="store"):
        EngineOptions(resume=True)


POSES = [Pose.from_mm(x, y, phi) for x in (-60, 0, 50) for y in (-50, 0, 70) for phi in (0.0, 0.2)] + [
    Pose(0.9, 0.0, 0.0)
]


def test_loopback_cluster_gives_the_same_numbers_as_the_local_run(reference_manip, loopback_cluster, tmp_path):
    opts = fast_options(segments=2)
    local = pose_frequencies(reference_manip, POSES, n_modes=3, options=opts, workers=1)
    engine = EngineOptions(scheduler=loopback_cluster, chunk=4, store=tmp_path / "chunks")
    remote = pose_frequencies(reference_manip, POSES, n_modes=3, options=opts, engine=engine)
    assert remote.status == local.status
    assert "unreachable" in remote.status
    np.testing.assert_array_equal(remote.frequencies_hz, local.frequencies_hz)
    np.testing.assert_array_equal(remote.in_plane, local.in_plane)
    assert len(list((tmp_path / "chunks").glob("*.pkl"))) == 5  # 19 poses in chunks of 4, streamed to disk


def test_unreachable_scheduler_is_a_clear_error(reference_manip):
    engine = EngineOptions(scheduler="tcp://127.0.0.1:9", chunk=1, connect_timeout_s=2.0)
    with pytest.raises(EngineError, match="scheduler"):
        pose_frequencies(reference_manip, POSES[:2], n_modes=1, options=fast_options(segments=2), engine=engine)


def test_spawn_pool_workers_ignore_ctrl_c_and_this_process_keeps_its_handler():
    """A terminal's Ctrl-C reaches the whole process group: the pool's workers ignore it (no traceback of theirs),
    this process keeps its handler (it is interrupted and stops them)."""
    import signal

    from fpm_sim.batch.engine import spawn_pool

    before = signal.getsignal(signal.SIGINT)
    with spawn_pool(1) as pool:
        in_worker = pool.apply(signal.getsignal, (signal.SIGINT,))
    assert in_worker == signal.SIG_IGN
    assert signal.getsignal(signal.SIGINT) is before
