"""Rerun replay (cnt_env.replay, docs/architecture.md "Replay", docs/architecture.md rule 13).

Recordings are written to temporary ``.rrd`` files and read back with
``rerun.chunk.RrdReader``: the recording id, the entity paths, one row per frame,
the logged reward equal to what ``step`` returned, no wall-clock timeline. Tests that
need rerun (the optional ``[rerun]`` extra) take the ``rr`` fixture and are skipped
without it; the env must never import rerun, and the episode file needs no rerun, so
those tests always run. The env is the small rod of tests/smallrod.py.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import gymnasium
import numpy as np
import pytest

from cnt_env import cli, replay, units
from cnt_env.io import load_trace, save_trace
from cnt_env.replay import (
    EPISODE_FORMAT,
    EpisodeFileError,
    EpisodeSaver,
    load_episode,
    save_episode,
)
from tests.smallrod import small

ENV_ID = "CNTDeposit-v0"
SMALL = small(pattern_every=3)
N_STEPS = 6  # the time limit of the recorded episodes
SEED = 7
# Entities every recorded episode holds (and one "/reward/<term>" per info["reward_<term>"]:
# reward_entities).
EPISODE_ENTITIES = {
    "/world/rod", "/world/trace", "/world/flow", "/top/rod", "/top/trace", "/top/flow",
    "/reward/total", "/reward/return", "/score/score", "/flow/vbar", "/flow/phi", "/events",
}  # fmt: skip
STATIC_ENTITIES = {"/world", "/world/substrate", "/world/target", "/top/target",
                   "/world/trace_before", "/top/trace_before"}  # fmt: skip


@pytest.fixture(scope="module")
def rr():
    return pytest.importorskip("rerun", reason='rerun-sdk not installed: pip install -e ".[rerun]"')


@pytest.fixture(scope="module")
def kw(tmp_path_factory: pytest.TempPathFactory) -> dict:
    return dict(SMALL, cache_dir=str(tmp_path_factory.mktemp("warm_cache")))


def make(kw: dict) -> gymnasium.Env:
    return gymnasium.make(ENV_ID, max_episode_steps=N_STEPS, **kw)


def actions(n: int, seed: int = 0) -> list[np.ndarray]:
    g = np.random.default_rng(seed)
    return [g.uniform(-1, 1, 2).astype(np.float32) for _ in range(n)]


def run_episode(env: gymnasium.Env, seed: int | None = SEED) -> tuple[list[float], list[dict]]:
    """One episode to its end with fixed actions; the rewards and infos of the steps."""
    env.reset(seed=seed)
    rewards, infos = [], []
    for a in actions(10 * N_STEPS):
        _, r, terminated, truncated, info = env.step(a)
        rewards.append(r)
        infos.append(info)
        if terminated or truncated:
            break
    return rewards, infos


def reward_terms(info: dict) -> list[str]:
    """The reward terms of a step's ``info`` (``reward_<term>`` keys), in order."""
    return [k for k in info if k.startswith("reward_")]


def reward_entities(info: dict) -> set[str]:
    return {"/reward/" + k.removeprefix("reward_") for k in reward_terms(info)}


def rrd_content(path: Path) -> dict[str, list]:
    """Entity -> its rows (every column but the row ids), in a canonical order, so that
    recordings can be compared whatever their chunking."""
    from rerun.chunk import RrdReader

    out: dict[str, list] = {}
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        cols = [n for n in batch.schema.names if "RowId" not in n]
        rows = zip(*(batch.column(n).to_pylist() for n in cols), strict=True)
        key = f"{chunk.entity_path}{' (static)' if chunk.is_static else ''}"
        out.setdefault(key, []).extend(repr(list(zip(cols, r, strict=True))) for r in rows)
    return {k: sorted(v) for k, v in out.items()}


# ---- without rerun ----------------------------------------------------------------------


def test_env_without_the_wrapper_never_imports_rerun(kw: dict) -> None:
    code = f"""
import sys, gymnasium, cnt_env
env = gymnasium.make({ENV_ID!r}, **{kw!r})
env.reset(seed=0)
for _ in range(3):
    env.step(env.action_space.sample())
a = 'rerun' in sys.modules
from cnt_env import replay  # the module and the episode file need no rerun either
from cnt_env.replay import EpisodeSaver
env = EpisodeSaver(env, sys.argv[1], tag="x")
env.reset(seed=0)
env.step(env.action_space.sample())
env.close()
print(a, 'rerun' in sys.modules, sorted(m for m in sys.modules if m.startswith('rerun')))
"""
    tmp = Path(kw["cache_dir"]) / "no_rerun"
    out = subprocess.run([sys.executable, "-c", code, str(tmp)], capture_output=True,
                         text=True, check=True, env=os.environ.copy()).stdout  # fmt: skip
    assert out.strip() == "False False []"
    assert [p.name for p in tmp.iterdir()] == ["x-s0-e0000.npz"]


def test_missing_rerun_says_how_to_install(monkeypatch: pytest.MonkeyPatch, kw: dict) -> None:
    monkeypatch.setitem(sys.modules, "rerun", None)  # import rerun -> ImportError
    with pytest.raises(ImportError, match=r'pip install -e "\.\[rerun\]"'):
        replay.import_rerun()
    with pytest.raises(ImportError, match="rerun"):
        replay.RerunRecorder(make(kw), "unused")
    assert cli.main(["replay", "x.npz", "--rrd", "x.rrd"]) == cli.EXIT_FAILED


def test_episode_file_round_trip(kw: dict, tmp_path: Path) -> None:
    env = EpisodeSaver(make(kw), tmp_path, tag="t")
    rewards, infos = run_episode(env)
    (path,) = env.paths
    assert path.name == f"t-s{SEED}-e0000.npz"
    assert replay.file_format(path) == EPISODE_FORMAT
    ep = load_episode(path)
    n = len(rewards)
    assert ep.n_steps == n and list(ep.step) == list(range(n + 1))
    assert ep.reward[1:].tolist() == rewards
    assert ep.sim_time[1:].tolist() == [i["sim_time"] for i in infos]
    assert list(ep.reward_term_names) == reward_terms(infos[0])
    for k, term in enumerate(ep.reward_term_names):
        assert ep.reward_terms[1:, k].tolist() == [i[term] for i in infos]
    assert ep.metrics[-1, ep.metric_names.index("score")] == infos[-1]["score"]
    assert ep.truncated[-1] and not ep.truncated[:-1].any() and ep.failure == ""
    sim = replay._simulator(env)  # the env's DepositionSim
    assert np.array_equal(ep.rod(n), sim.suspended_nodes)
    assert np.array_equal(ep.trace, sim.trace()) and ep.trace_len[-1] == sim.n_trace
    # the target starts at the contact point at reset (laid nodes may slide a little since)
    assert ep.target[0] == pytest.approx(ep.trace[ep.n_start - 1, [0, 2]], abs=0.1)
    assert ep.meta["recording_id"] == f"t-s{SEED}-e0000" and ep.meta["seed"] == SEED
    # a round trip is exact
    again = load_episode(save_episode(tmp_path / "again.npz", ep))
    arrays = ("step", "sim_time", "flow", "reward", "reward_terms", "metrics", "rod_nodes",
              "rod_offsets", "trace_len", "trace", "target", "terminated", "truncated")  # fmt: skip
    for name in arrays:
        assert np.array_equal(getattr(again, name), getattr(ep, name), equal_nan=True), name
    assert again.meta == ep.meta and again.metric_names == ep.metric_names


def test_episode_file_rejects_bad_files(kw: dict, tmp_path: Path) -> None:
    env = EpisodeSaver(make(kw), tmp_path / "ep", tag="t")
    run_episode(env)
    good = dict(np.load(env.paths[0], allow_pickle=False))

    def write(name: str, **changes) -> Path:
        entries = {**good, **changes}
        entries = {k: v for k, v in entries.items() if v is not None}
        path = tmp_path / name
        np.savez(path, **entries)
        return path

    cases = {
        "missing": (tmp_path / "nope.npz", "no such file"),
        "text": (tmp_path / "text.npz", "not an .npz"),
        "foreign": (write("foreign.npz", format=None), "no 'format' entry"),
        "trace": (write("trace.npz", format=np.array("cnt_env.trace")), "not a cnt_env episode"),
        "newer": (write("newer.npz", format_version=np.array(99)), "newer"),
        "no_rods": (write("no_rods.npz", rod_nodes=None), "missing rod_nodes"),
        "offsets": (write("offsets.npz", rod_offsets=good["rod_offsets"][::-1].copy()),
                    "rod_offsets"),
        "nan": (write("nan.npz", reward=np.full_like(good["reward"], np.nan)), "NaN"),
        "shape": (write("shape.npz", flow=good["flow"][:, :1]), "flow must have shape"),
        "meta": (write("meta.npz", meta=np.array("[1, 2]")), "meta"),
    }  # fmt: skip
    (tmp_path / "text.npz").write_text("not an archive")
    for path, message in cases.values():  # a failure names the file, so the case
        with pytest.raises(EpisodeFileError, match=message):
            load_episode(path)


# ---- recordings -------------------------------------------------------------------------


def test_recorded_episode_reads_back(rr, kw: dict, tmp_path: Path) -> None:
    from rerun.chunk import RrdReader

    env = replay.RerunRecorder(make(kw), tmp_path, tag="test")
    rewards, infos = run_episode(env)
    n = len(rewards)
    assert n == N_STEPS  # the time limit, not a failure
    (path,) = env.paths
    assert path == tmp_path / f"test-s{SEED}-e0000.rrd"
    (store,) = RrdReader(path).recordings()
    assert store.recording_id == f"test-s{SEED}-e0000" == env.recording_ids[0]
    assert store.application_id == replay.APPLICATION_ID

    got = replay.read_rrd(path)
    assert got["blueprints"] == 1
    assert got["timelines"] == ["sim_time", "step"]  # no log_time: reproducible files
    assert EPISODE_ENTITIES | reward_entities(infos[0]) <= set(got["rows"])
    assert STATIC_ENTITIES <= set(got["static"])
    for entity in ("/world/rod", "/world/trace", "/top/rod", "/world/flow", "/score/score",
                   "/flow/vbar"):  # fmt: skip
        assert got["rows"][entity] == n + 1, entity  # the reset frame and every step
    for entity in {"/reward/total", "/reward/return"} | reward_entities(infos[0]):
        assert got["rows"][entity] == n, entity
    assert got["scalars"]["/reward/total"] == list(enumerate(rewards, start=1))
    for term in reward_terms(infos[0]):
        entity = "/reward/" + term.removeprefix("reward_")
        assert got["scalars"][entity] == [(i, info[term]) for i, info in enumerate(infos, 1)]
    assert got["scalars"]["/score/score"][-1] == (n, infos[-1]["score"])
    assert got["scalars"]["/flow/phi"][1:] == [
        (i, info["flow_phi"]) for i, info in enumerate(infos, start=1)
    ]
    assert got["texts"][0].startswith(f"reset: target {infos[0]['target']}")
    assert got["texts"][-1].startswith(f"episode end at step {n}, truncated")

    # the sim_time timeline is info["sim_time"] (tau; a duration, shown as seconds)
    from rerun.chunk import RrdReader as _Reader

    times = []
    for chunk in _Reader(path).stream():
        if chunk.entity_path == "/reward/total" and not chunk.is_static:
            times += [t.total_seconds() for t in chunk.to_record_batch().column("sim_time")
                      .to_pylist()]  # fmt: skip
    assert sorted(times) == pytest.approx([i["sim_time"] for i in infos], abs=1e-9)


@pytest.mark.parametrize("stream", [False, True])
def test_two_episodes_give_two_recordings(rr, kw: dict, tmp_path: Path, stream: bool) -> None:
    env = replay.RerunRecorder(make(kw), tmp_path / "a", tag="w0", save_episodes=True,
                               stream=stream)  # fmt: skip
    env.reset(seed=SEED)
    for a in actions(2):
        env.step(a)
    run_episode(env, seed=None)  # cuts the first short; the seed part of the id stays
    env.close()
    assert env.recording_ids == [f"w0-s{SEED}-e0000", f"w0-s{SEED}-e0001"]
    got = [replay.read_rrd(p) for p in env.paths]
    assert [g["recordings"] for g in got] == [[env.recording_ids[0]], [env.recording_ids[1]]]
    assert got[0]["rows"]["/reward/total"] == 2 and "cut short" in got[0]["texts"][-1]
    assert got[1]["rows"]["/reward/total"] == N_STEPS and "truncated" in got[1]["texts"][-1]
    assert [load_episode(p).n_steps for p in env.episode_paths] == [2, N_STEPS]
    # two wrapper instances (e.g. two SubprocVecEnv workers) never share an id
    a = replay.RerunRecorder(make(kw), tmp_path / "b")
    b = replay.RerunRecorder(make(kw), tmp_path / "b")
    run_episode(a)
    run_episode(b)
    assert a.tag != b.tag and set(a.recording_ids).isdisjoint(b.recording_ids)
    assert len(list((tmp_path / "b").glob("*.rrd"))) == 2


def test_vector_env_workers_write_their_own_recordings(rr, kw: dict, tmp_path: Path) -> None:
    def factory(rank: int):
        return lambda: replay.RerunRecorder(make(kw), tmp_path, tag=f"rank{rank}")

    envs = gymnasium.vector.SyncVectorEnv([factory(0), factory(1)])
    envs.reset(seed=[SEED, SEED + 1])
    for a in actions(N_STEPS + 1):  # the autoreset starts a second episode in each
        envs.step(np.stack([a, -a]))
    envs.close()  # finishes the second episodes (cut short)
    names = sorted(p.stem for p in tmp_path.glob("*.rrd"))
    assert names == [f"rank0-s{SEED}-e0000", f"rank0-s{SEED}-e0001",
                     f"rank1-s{SEED + 1}-e0000", f"rank1-s{SEED + 1}-e0001"]  # fmt: skip
    for name in names:
        assert replay.read_rrd(tmp_path / f"{name}.rrd")["recordings"] == [name]


def test_same_episode_same_recording(rr, kw: dict, tmp_path: Path) -> None:
    """Log time is off and no wall-clock property is sent: the same seeded episode
    gives the same recording (up to rerun's row ids), collected or streamed step by step
    (but for the trace: a streamed one is drawn as it was at each step), or replayed
    from its episode file."""
    paths, episodes = {}, {}
    for name, stream in (("one", False), ("two", False), ("streamed", True)):
        env = replay.RerunRecorder(make(kw), tmp_path / name, tag="same", save_episodes=True,
                                   stream=stream)  # fmt: skip
        run_episode(env)
        paths[name], episodes[name] = env.paths[0], env.episode_paths[0]
    one = rrd_content(paths["one"])
    assert one == rrd_content(paths["two"])
    replayed = tmp_path / "replayed.rrd"
    assert replay.record_episode(episodes["streamed"], replayed) == env.recording_ids[0]
    assert rrd_content(replayed) == one
    streamed = rrd_content(paths["streamed"])
    assert streamed.keys() == one.keys()
    for entity in one:
        if "trace" not in entity:  # laid nodes still in the solve may slide a little
            assert streamed[entity] == one[entity], entity


def _synthetic_trace(path: Path) -> Path:
    s = np.linspace(0.0, 6 * np.pi, 200)
    trace = np.column_stack([5 * np.cos(s) + 0.2 * s, np.zeros_like(s), 5 * np.sin(s)])
    params = units.paper_groups("coil").as_dict()
    config = {"preset": "coil", "substrate": "flat", "seed": 3}
    stats = {"time": 123.5, "steps": 456, "newton_iterations": 900, "deposited_length": 90.0}
    suspended = np.column_stack([np.full(20, trace[-1, 0]), np.arange(20.0),
                                 np.full(20, trace[-1, 2])])  # fmt: skip
    return save_trace(path, trace, params, config, stats, suspended)


def test_cli_replay_of_a_trace_and_an_episode(
    rr, kw: dict, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    trace = _synthetic_trace(tmp_path / "trace.npz")
    out = tmp_path / "trace.rrd"
    assert cli.main(["replay", str(trace), "--rrd", str(out), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed == {"file": str(trace), "kind": "cnt_env.trace", "rrd": str(out),
                       "recording_id": "run-coil-s3", "video": None}  # fmt: skip
    got = replay.read_rrd(out)
    assert got["recordings"] == ["run-coil-s3"]
    assert set(got["timelines"]) == {"step", "sim_time", "trace_node"}
    assert got["rows"]["/world/trace"] == replay.SAVED_RUN_FRAMES + 1  # reveal + final state
    assert got["rows"]["/world/rod"] == 1
    assert got["scalars"]["/solver/newton_iterations"] == [(456, 900.0)]

    env = EpisodeSaver(make(kw), tmp_path / "ep", tag="cli")
    rewards, _ = run_episode(env)
    out = tmp_path / "episode.rrd"
    assert cli.main(["replay", str(env.paths[0]), "--rrd", str(out), "--recording-id", "r1"]) == 0
    assert "rerun " in capsys.readouterr().out  # says how to open it
    got = replay.read_rrd(out)
    assert got["recordings"] == ["r1"]
    assert got["scalars"]["/reward/total"] == list(enumerate(rewards, start=1))

    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, x=np.zeros(3))
    assert cli.main(["replay", str(foreign), "--rrd", str(tmp_path / "f.rrd")]) == 2
    assert "neither" in capsys.readouterr().err
    assert cli.main(["replay", str(tmp_path / "nope.npz"), "--rrd", str(out)]) == 2


def test_cli_replay_writes_a_video_of_a_trace_and_an_episode(
    kw: dict, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("imageio", reason="the video extra (pip install -e '.[video]')")
    trace = _synthetic_trace(tmp_path / "trace.npz")
    gif = tmp_path / "trace.gif"
    assert cli.main(["replay", str(trace), "--video", str(gif)]) == 0
    assert gif.read_bytes()[:6] in (b"GIF87a", b"GIF89a")
    env = EpisodeSaver(make(kw), tmp_path / "ep", tag="video")
    run_episode(env)
    mp4 = tmp_path / "episode.mp4"
    assert cli.main(["replay", str(env.paths[0]), "--video", str(mp4)]) == 0
    assert mp4.stat().st_size > 1000 and b"ftyp" in mp4.read_bytes()[:64]
    capsys.readouterr()
    assert cli.main(["replay", str(trace)]) == 2  # neither --rrd nor --video
    assert cli.main(["replay", str(trace), "--video", str(tmp_path / "x.avi")]) == 2
    assert ".gif, .mp4" in capsys.readouterr().err
    assert not (tmp_path / "x.avi").exists()


def test_cli_run_records_the_run(rr, tmp_path: Path) -> None:
    out = tmp_path / "run.rrd"
    argv = ["run", "--deposit", "5", "--Hbar", "40", "--transient", "0", "--delta", "1",
            "--rrd", str(out), "--json"]  # fmt: skip
    assert cli.main(argv) == 0
    assert Path(f"{out}.json").exists()  # the resolved config beside the output
    got = replay.read_rrd(out)
    assert got["recordings"] == ["run-coil-s0"]
    assert got["timelines"] == ["sim_time", "step"]
    rows = got["rows"]["/world/rod"]
    assert rows == got["rows"]["/world/trace"] >= 3  # start, samples, end
    steps = [s for s, _ in got["scalars"]["/metrics/deposited_length"]]
    assert steps == sorted(steps) and steps[0] == 0
    assert got["scalars"]["/metrics/deposited_length"][-1][1] >= 5.0
    assert got["texts"][0].startswith("start") and got["texts"][-1].startswith("end of the run")
    assert cli.main(["run", "--deposit", "5", "--rrd", str(out), "--out", str(out)]) == 2


# ---- video (the optional [video] extra) -------------------------------------------------


def synthetic_episode(n_steps: int = 4, meta: dict | None = None) -> replay.Episode:
    """A small episode without the env: a trace that grows along +x, a rod above it."""
    f = n_steps + 1
    s = np.linspace(0.0, 20.0, 10 + 5 * n_steps)
    trace = np.column_stack([s, np.zeros_like(s), np.sin(s / 3)])
    trace_len = np.arange(f) * 5 + 10
    rods = [np.column_stack([np.full(6, trace[k - 1, 0]), np.arange(6.0),
                             np.full(6, trace[k - 1, 2])]) for k in trace_len]  # fmt: skip
    return replay.Episode(
        step=np.arange(f), sim_time=15.0 * np.arange(f), flow=np.tile([0.05, 0.3], (f, 1)),
        reward=np.full(f, 0.1), reward_terms=np.zeros((f, 0)), reward_term_names=(),
        metrics=np.zeros((f, 0)), metric_names=(), rod_nodes=np.concatenate(rods),
        rod_offsets=np.arange(f + 1) * 6, trace_len=trace_len, trace=trace,
        target=np.array([[s[9], 0.0], [30.0, 5.0]]),
        terminated=np.zeros(f, bool), truncated=np.arange(f) == n_steps,
        meta={"recording_id": "synthetic", "target": "line", "substrate": "stepped",
              "params": {"Hbar": 30.0}, "vbar_max": 0.13, **(meta or {})},
    )  # fmt: skip


ROUTE = {"width": 4.0, "pads": [[[25.0, 0.0], [25.0, 8.0]]],
         "keepouts": [[[5.0, 8.0], [15.0, 8.0], [15.0, 14.0]]]}  # fmt: skip


def test_route_is_drawn_in_the_still_and_the_recording(rr, tmp_path: Path) -> None:
    ep = synthetic_episode(3, meta={"route": ROUTE})
    geometry = replay.episode.route_geometry(ep.meta)
    assert geometry["width"] == 4.0 and geometry["pads"][0].shape == (2, 2)
    kw = replay.still.episode_view_kwargs(ep, 3)
    assert kw["corridor"] == 4.0 and len(kw["pads"]) == len(kw["keepouts"]) == 1
    _, _, z0, z1 = replay.video.episode_extent(ep)
    assert z1 > 14.0 and z0 < -4.0  # the keep-out and the corridor are in view
    assert replay.render_top_view(ep, tmp_path / "still.png").exists()
    replay.record_episode(ep, tmp_path / "route.rrd")
    static = set(replay.read_rrd(tmp_path / "route.rrd")["static"])
    assert {"/top/corridor", "/top/pads", "/top/keepouts", "/world/pads"} <= static
    # a malformed route only loses the drawing
    assert replay.episode.route_geometry({"route": {"width": -1}}) is None
    assert replay.episode.route_geometry({"route": {"width": 2, "keepouts": [[[0, 0]]]}}) is None
    replay.record_episode(synthetic_episode(1), tmp_path / "plain.rrd")
    assert "/top/corridor" not in replay.read_rrd(tmp_path / "plain.rrd")["static"]


@pytest.fixture(scope="module")
def iio():
    pytest.importorskip(
        "imageio_ffmpeg", reason='imageio-ffmpeg missing: pip install -e ".[video]"'
    )
    return pytest.importorskip("imageio.v3", reason='imageio missing: pip install -e ".[video]"')


def test_episode_gif_reads_back(iio, tmp_path: Path) -> None:
    ep = synthetic_episode(4)
    path = save_episode(tmp_path / "ep.npz", ep)
    gif = replay.write_video(path, tmp_path / "ep.gif", fps=5, size=(320, 240))
    frames = iio.imread(gif, index=None)
    assert frames.shape == (ep.n_steps + 1, 240, 320, 3)  # the reset frame and every step
    assert iio.immeta(gif)["duration"] == 200  # ms per frame at 5 fps
    # the extent is fixed: the tick labels left of the axes never change (raw frames: a
    # GIF's palette is chosen per frame)
    raw = list(replay.episode_frames(ep, size=(320, 240)))
    assert len(raw) == len(frames) and raw[0].shape == frames[0].shape
    assert np.array_equal(raw[0][:, :40], raw[-1][:, :40])
    assert not np.array_equal(raw[0], raw[-1])  # the trace grew
    # every other step (and the last), from an Episode
    again = replay.write_video(ep, tmp_path / "half.gif", size=(320, 240), every=3)
    assert iio.imread(again, index=None).shape[0] == 3  # steps 0, 3, 4


def test_video_from_frames_and_mp4(iio, tmp_path: Path) -> None:
    import imageio

    frames = [np.full((64, 96, 3), 40 * i, dtype=np.uint8) for i in range(5)]
    gif = replay.write_video(frames, tmp_path / "f.gif", fps=10)
    assert iio.imread(gif, index=None).shape == (5, 64, 96, 3)
    mp4 = replay.write_video(iter(frames), tmp_path / "f.mp4", fps=10)
    reader = imageio.v2.get_reader(mp4)
    assert reader.count_frames() == 5 and reader.get_meta_data()["size"] == (96, 64)
    reader.close()
    with pytest.raises(ValueError, match=r"\.gif or \.mp4"):
        replay.write_video(frames, tmp_path / "f.avi")
    with pytest.raises(ValueError, match="shape"):
        replay.write_video([frames[0], frames[0][:32]], tmp_path / "g.gif")
    with pytest.raises(ValueError, match="uint8"):
        replay.write_video([frames[0].astype(float)], tmp_path / "h.gif")
    with pytest.raises(ValueError, match="extent"):
        replay.write_video(synthetic_episode(1), tmp_path / "e.gif", extent=(1, 0, 0, 1))


def test_missing_imageio_says_how_to_install(monkeypatch: pytest.MonkeyPatch, tmp_path) -> None:
    monkeypatch.setitem(sys.modules, "imageio", None)
    with pytest.raises(ImportError, match=r'pip install -e "\.\[video\]"'):
        replay.write_video(synthetic_episode(1), tmp_path / "x.gif")


def test_saved_run_video(iio, tmp_path: Path) -> None:
    """A trace file as a video: the trace revealed in order of deposition, one extent."""
    saved = load_trace(_synthetic_trace(tmp_path / "long.npz"))
    trace = save_trace(tmp_path / "trace.npz", saved["trace"][:12], saved["params"],
                       saved["config"], saved["stats"], saved["suspended"])  # fmt: skip
    gif = replay.write_video(trace, tmp_path / "trace.gif", size=(240, 240))
    frames = iio.imread(gif, index=None)
    assert frames.shape == (11, 240, 240, 3)  # 2, 3, ..., 12 nodes shown
    raw = list(replay.video.trace_frames(saved, max_frames=5, size=(240, 240)))
    assert len(raw) == 5 and np.array_equal(raw[0][:, :30], raw[-1][:, :30])
