"""`marl record`: videos that decode as asked, exact replays of stored games, clear errors, flat memory."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tracemalloc
from pathlib import Path

import imageio.v2 as iio2
import imageio.v3 as iio
import numpy as np
import pytest

from selfplay_cli.cli import main
from selfplay_cli.envs import get_env
from selfplay_cli.errors import MarlError
from selfplay_cli.evaluation.lineup import lineup
from selfplay_cli.league.store import League
from selfplay_cli.play import Game, play
from selfplay_cli.play.replay import ReplayError, decode_actions, encode_actions, replay_policies
from selfplay_cli.play.schedule import rounds
from selfplay_cli.policies import ScriptedPolicy
from selfplay_cli.policies.network import Arch, build_network
from selfplay_cli.policies.snapshot_format import SnapshotMeta, save_snapshot
from selfplay_cli.record import VideoSettings, record_game, stop_rule
from selfplay_cli.results import GameResult, Rules


def make_snapshot(path: Path, run: str, name: str, seed: int, env_options: dict | None = None) -> Path:
    arch = Arch(hidden=(16, 16))
    net = build_network((8, 6), 3, arch, seed=seed)
    save_snapshot(path, net, SnapshotMeta(env="pong", env_options=env_options or {}, obs_shape=(8, 6), n_actions=3,
                                          arch=arch, run=run, name=name, algo="ppo", step=100 * seed, episode=seed))
    return path


@pytest.fixture(scope="module")
def home(tmp_path_factory) -> Path:
    """A league with a one-network snapshot r1/ep10 (games to 2 points, so whole games are short) and a
    two-learner run r2 (ep5-left, ep5-right), imported as any user would."""
    h = tmp_path_factory.mktemp("record") / "league"
    files = tmp_path_factory.mktemp("files")
    snaps = [make_snapshot(files / "a.safetensors", "r1", "ep10", 1, {"points_to_win": 2}),
             make_snapshot(files / "l.safetensors", "r2", "ep5-left", 2),
             make_snapshot(files / "r.safetensors", "r2", "ep5-right", 3)]
    for f in snaps:
        assert main(["checkpoint", "import", str(f), "--home", str(h)]) == 0
    return h


def run(capsys, home: Path, *args: str) -> tuple[int, str, str]:
    code = main(["record", *args, "--home", str(home)])
    out = capsys.readouterr()
    return code, out.out, out.err


def run_json(capsys, home: Path, *args: str) -> list[dict]:
    code, out, err = run(capsys, home, *args, "--json")
    assert code == 0, err
    return json.loads(out)


def mp4_frames(path: Path) -> tuple[np.ndarray, dict]:
    reader = iio2.get_reader(path)
    try:
        return np.stack([f for f in reader.iter_data()]), reader.get_meta_data()
    finally:
        reader.close()


def differs(a: np.ndarray, b: np.ndarray) -> bool:
    return int(np.abs(a.astype(np.int16) - b).max()) > 40  # well above H.264's rounding


# ---------------------------------------------------------------------------------------------------------------
def test_mp4_decodes_with_the_frame_count_size_and_fps_asked_for(home, tmp_path, capsys):
    out = tmp_path / "clip.mp4"
    (rec,) = run_json(capsys, home, "--ckpt", "ep10", "--max-steps", "40", "--size", "160x80", "--fps", "30",
                      "--hold", "0.5", "--out", str(out))
    assert rec["path"] == str(out) and rec["players"] == ["r1/ep10", "cpu"]
    assert rec["length"] == 40 and rec["truncated"] and rec["frames"] == 41 + 15  # serve, 40 steps, 0.5 s held
    frames, meta = mp4_frames(out)
    assert frames.shape == (56, 80, 160, 3)
    assert meta["fps"] == 30 and meta["codec"] == "h264" and meta["pix_fmt"].startswith("yuv420p")
    assert all(differs(frames[i], frames[i + 1]) for i in range(40)), "the ball moves every step"
    held = frames[40:]
    assert max(np.abs(f.astype(np.int16) - held[0]).max() for f in held) <= 2, "the final frame is held"
    assert not list(tmp_path.glob(".*")), "no temporary file left beside the video"


def test_same_seed_same_frames_and_another_seed_another_game(home, tmp_path, capsys):
    args = ("--ckpt", "ep10", "--vs", "random", "--max-steps", "30", "--size", "96x48", "--hold", "0")
    run_json(capsys, home, *args, "--seed", "3", "--out", str(tmp_path / "a.mp4"))
    run_json(capsys, home, *args, "--seed", "3", "--out", str(tmp_path / "b.mp4"))
    run_json(capsys, home, *args, "--seed", "4", "--out", str(tmp_path / "c.mp4"))
    a, b, c = (mp4_frames(tmp_path / f"{x}.mp4")[0] for x in "abc")
    assert a.shape == (31, 48, 96, 3) and np.array_equal(a, b)
    assert any(differs(x, y) for x, y in zip(a, c, strict=True))


def test_game_id_replays_the_stored_game_exactly(home, tmp_path, capsys):
    code = main(["match", "ep10", "cpu", "--games", "2", "--home", str(home), "--json", "--quiet"])
    report = json.loads(capsys.readouterr().out)
    assert code == 0 and len(report["game_ids"]) == 2
    gid = report["game_ids"][1]
    with League.open(home) as league:
        stored = league.ledger.game(gid)
    assert stored.actions is not None and stored.match_params["env_options"] == {"points_to_win": 2}
    (rec,) = run_json(capsys, home, "--game", str(gid), "--size", "96x48", "--hold", "0")
    assert rec["game_id"] == gid and rec["seed"] == stored.seed
    assert rec["scores"] == [int(s) for s in stored.scores] and max(rec["scores"]) == 2
    assert rec["length"] == stored.length and not rec["truncated"]
    assert rec["players"] == ["cpu", "r1/ep10"], "seat order as played: the second game of a pair swaps seats"
    path = Path(rec["path"])
    assert path == home / "videos" / f"game{gid}-cpu-vs-r1-ep10-s{stored.seed}.mp4"
    assert len(mp4_frames(path)[0]) == stored.length + 1


@pytest.mark.slow
def test_a_gif_is_small_real_time_and_each_picture_once(home, tmp_path, capsys):
    """300 steps of pong at 60 fps: every third frame stored (20 a second, at the game's own pace), the held final
    frame stored once and shown for its second, one palette for the whole file, 640 pixels wide. Stored a frame per
    step with a palette each (as before) the same clip took about 1.2 MB."""
    out = tmp_path / "clip.gif"
    (rec,) = run_json(capsys, home, "--ckpt", "cpu", "--vs", "cpu", "--env", "pong", "--max-steps", "300", "--out",
                      str(out))
    assert out.stat().st_size < 400_000, out.stat().st_size
    assert rec["format"] == "gif" and rec["fps"] == 60 and rec["frames"] == 301 + 60  # serve, 300 steps, 1 s held
    assert rec["stored_frames"] == 101  # frames 0, 3, ..., 300; the held ones repeat frame 300
    frames = iio.imread(out, index=None)
    assert frames.shape[0] == 101 and frames.shape[2] == 640 and rec["size"] == f"640x{frames.shape[1]}"
    from selfplay_cli.record import gif_frames

    global_palette, stored = gif_frames(out.read_bytes())
    assert global_palette and not any(f.local_palette for f in stored)
    assert [f.delay for f in stored] == [5] * 100 + [102]  # 1/20 s each; the last: 61 frames of 1/60 s
    assert sum(f.delay for f in stored) == round(100 * 361 / 60)
    assert differs(frames[0], frames[50])

    wide = tmp_path / "wide.gif"  # --max-width 0: the frames' own width
    (rec,) = run_json(capsys, home, "--ckpt", "cpu", "--vs", "cpu", "--env", "pong", "--max-steps", "10", "--hold",
                      "0", "--max-width", "0", "--out", str(wide))
    assert iio.imread(wide, index=None).shape[2] == 800 and rec["size"].startswith("800x")


def test_a_gif_stores_a_picture_once_however_long_it_stays(tmp_path):
    """A board between moves: frames that repeat the last stored one are not stored, it stays on screen longer."""
    from selfplay_cli.record.video import VideoWriter

    a, b = np.zeros((32, 48, 3), np.uint8), np.full((32, 48, 3), 200, np.uint8)
    path = tmp_path / "board.gif"
    with VideoWriter(path, fps=10, fmt="gif") as video:
        for frame in [a] * 10 + [b] * 5 + [a] * 3:
            video.write(frame)
    frames = iio.imread(path, index=None)
    assert frames.shape[:3] == (3, 32, 48) and frames[1].mean() > 150 > frames[2].mean()
    assert [iio.immeta(path, index=i)["duration"] for i in range(3)] == [1000, 500, 300]  # ms on screen
    assert (video.frames, video.stored) == (18, 3)


def test_a_users_board_game_records_with_its_band_through_the_cli(tmp_path, capsys):
    """`marl record` of a PettingZoo game (the game's own 96 x 96 render("rgb_array")): enlarged to 384 wide, the
    band under it; each picture once in a GIF."""
    home = tmp_path / "league"
    recs = run_json(capsys, home, "--ckpt", "random", "--vs", "random", "--env", "tests.games.tictactoe:env",
                    "--games", "2", "--out", str(tmp_path / "videos"))
    for rec in recs:
        frames = mp4_frames(Path(rec["path"]))[0]
        assert frames.shape[0] == rec["length"] + 1 + 2 and frames.shape[2] == 384 and frames.shape[1] > 384 + 40
    (rec,) = run_json(capsys, home, "--ckpt", "random", "--vs", "random", "--env", "tests.games.tictactoe:env",
                      "--out", str(tmp_path / "ttt.gif"))
    assert rec["stored_frames"] == rec["length"] + 1 and rec["frames"] == rec["length"] + 1 + 2  # 2 held: 1 s


class _Kept:
    """Stands in for the video writer: keeps every frame as it was handed over."""

    def __init__(self, path, fps=60, size=None, fmt="mp4", max_width=0):
        self.kept: list[np.ndarray] = []
        _Kept.last = self

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def write(self, frame):
        self.kept.append(frame.copy())

    @property
    def frames(self):
        return len(self.kept)

    stored = frames

    @property
    def frame_shape(self):
        return self.kept[0].shape

    def out_size(self, width, height):
        return width, height


class _Seen:
    """Stands in for a game's renderer: draws with it and keeps each picture with the score and step it showed."""

    def __init__(self, inner):
        self.inner, self.seen = inner, []

    def __getattr__(self, name):
        return getattr(self.inner, name)  # seat_colour, where the game has one

    def draw(self, core, game):
        picture = self.inner.draw(core, game)
        self.seen.append((picture, core.score[:, game].copy(), int(core.steps[game])))
        return picture


def _score(x: float) -> str:
    return f"{round(float(x), 2):g}"  # as the band shows a score: whole, else to two decimals


@pytest.mark.parametrize(("env", "labels", "expected"), [
    ("tests.games.tictactoe:env", ("alice", "bob"), lambda s: [f"x: alice  {_score(s[0])}", f"o: bob  {_score(s[1])}"]),
    ("pong", ("r1/ep10", "cpu"), lambda s: [f"left: r1/ep10  {_score(s[0])}", f"right: cpu  {_score(s[1])}"]),
    ("lander", ("heuristic", "heuristic"), lambda s: [f"team: heuristic x2  return {_score(s.sum())}"]),
])
def test_every_recording_carries_names_score_step_and_game_number(monkeypatch, tmp_path, env, labels, expected):
    """A user's game (the game's own render("rgb_array")), pong and the lander: under the game's own picture, a band
    with the players' names per seat, the running score per side, the game's number and the step."""
    from selfplay_cli.record import recorder

    spec = get_env(env)
    monkeypatch.setattr(recorder, "VideoWriter", _Kept)
    renderer = _Seen(spec.make_renderer())
    bots = [ScriptedPolicy(spec.name, next(iter(spec.bots)), seed=s) for s in range(2)]
    rec = record_game(spec, bots, Game(3, (0, 1)), tmp_path / "v.mp4", VideoSettings(fps=10, hold=0.2),
                      labels=labels, renderer=renderer, heading="game 2 of 3",
                      stop_when=stop_rule(spec, {}, max_steps=12))
    frames = _Kept.last.kept
    assert len(frames) == len(renderer.seen) + 2  # one per picture, the last held for 0.2 s
    picture = renderer.seen[0][0]
    scale = max(1, -(-360 // picture.shape[1]))  # a narrow board is enlarged so that its band's text fits
    height, width = picture.shape[0] * scale, picture.shape[1] * scale
    assert frames[0].shape[0] > height and frames[0].shape[1] == width, "a band under the game's picture"
    for frame, (picture, _, _) in zip(frames, renderer.seen, strict=False):
        assert np.array_equal(frame[:height], picture.repeat(scale, 0).repeat(scale, 1)), "the game's own picture"

    from selfplay_cli.record import CaptionBand

    band = CaptionBand(spec, labels, "game 2 of 3", getattr(renderer, "seat_colour", None))
    for frame, (picture, score, step) in zip(frames, renderer.seen, strict=False):
        tail = {"result": " · final", "time limit": " · time limit"}.get(rec.ended, " · stopped")
        status = f"step {step}{tail if step == rec.result.length else ''}"
        assert np.array_equal(frame, band(picture, score, status)), f"step {step}: the band shows {status}"
    final = renderer.seen[-1][1]
    assert band.lines(final, f"step {rec.result.length}")[:-1] == expected(final)
    assert band.lines(final, "step 5")[-1] == "game 2 of 3 · step 5"
    assert not np.array_equal(frames[1][height:], frames[2][height:]), "the step changes from frame to frame"
    assert rec.result.length == renderer.seen[-1][2]


def test_a_two_learner_snapshot_faces_its_partner_by_default(home, capsys):
    recs = run_json(capsys, home, "--ckpt", "ep5", "--max-steps", "5", "--games", "2", "--size", "64x32", "-q")
    assert [r["players"] for r in recs] == [["r2/ep5-left", "r2/ep5-right"]] * 2
    assert [Path(r["path"]).name for r in recs] == [f"r2-ep5-left-vs-ep5-right-s{i}.mp4" for i in (0, 1)]
    assert all((home / "videos" / Path(r["path"]).name).exists() for r in recs)
    (rec,) = run_json(capsys, home, "--ckpt", "r2/ep5-right", "--max-rallies", "1", "--size", "64x32", "--hold", "0")
    assert rec["players"] == ["r2/ep5-left", "r2/ep5-right"], "either half of a team records the team, seats kept"
    assert rec["length"] < 1000


def test_lineup_seats_teams_singles_and_opponents(tmp_path):
    with League.open(tmp_path / "lg") as league:
        league.roster.create_run("t", "pong", {})
        for seat in ("left", "right"):  # as `marl train --agents 2` files them
            league.roster.add_snapshot(env="pong", run="t", name=f"ep90-{seat}", path="x", sha256="0",
                                       meta={"learner": seat})
        league.roster.add_snapshot(env="pong", run="t", name="solo", path="x", sha256="0", meta={"learner": "learner"})
        names = lambda lu: [p.full_name for p in lu.players]  # noqa: E731
        assert names(lineup(league, "ep90")) == ["t/ep90-left", "t/ep90-right"]
        assert lineup(league, "t/ep90-right").focus == 1
        assert names(lineup(league, "t/ep90-right", vs="cpu")) == ["cpu", "t/ep90-right"]
        assert names(lineup(league, "solo")) == ["t/solo", "cpu"]
        assert names(lineup(league, "solo", vs="ep90")) == ["t/solo", "t/ep90-right"]
        assert lineup(league, "ep90").file_stem(7) == "t-ep90-left-vs-ep90-right-s7"
        with pytest.raises(MarlError, match="team of 2 snapshots"):
            lineup(league, "ep90", vs="cpu")


@pytest.mark.parametrize(("args", "says"), [
    (["--ckpt", "nope"], "no policy named 'nope'"),
    (["--ckpt", "ep10", "--size", "800x401"], "--size 800x401: width and height must be even"),
    (["--ckpt", "ep10", "--size", "big"], "--size must look like WIDTHxHEIGHT"),
    (["--ckpt", "ep10", "--out", "{blocker}/clip.mp4"], "is a file, not a folder"),
    (["--ckpt", "ep10", "--fps", "0"], "--fps must lie between 1 and 240"),
    (["--ckpt", "ep10", "--games", "0"], "--games must be at least 1"),
    (["--ckpt", "ep10", "--max-width", "8", "--out", "{tmp}/v.gif"], "--max-width must be 0 (no limit) or lie"),
    (["--game", "99999"], "no game with id 99999"),
    ([], "--ckpt POLICY"),
])
def test_mistakes_are_one_clear_line_and_leave_no_file(home, tmp_path, capsys, args, says):
    blocker = tmp_path / "blocker"
    blocker.write_text("a file where a folder should be")
    before = sorted((home / "videos").glob("*")) if (home / "videos").exists() else []
    args = [a.format(blocker=blocker, tmp=tmp_path) for a in args]
    code, out, err = run(capsys, home, *args, *([] if "--out" in args else ["--out", str(tmp_path / "v.mp4")]))
    assert code == 2 and out == ""
    assert err.startswith("marl: error: ") and says in err and err.count("\n") == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["blocker"]
    assert (sorted((home / "videos").glob("*")) if (home / "videos").exists() else []) == before


def test_games_without_actions_or_that_no_longer_replay_are_refused(home, tmp_path, capsys):
    assert main(["match", "ep10", "random", "--games", "2", "--home", str(home), "--quiet"]) == 0
    capsys.readouterr()
    with League.open(home) as league:
        played = league.ledger.game(league.ledger.games(variant=None).game_id[-1])  # (ep10 plays to 2 points)
        training = league.ledger.create_match("pong", "training", {"run": "r1"})
        tampered = decode_actions(played.actions, 2).copy()
        tampered[:, 0] = (tampered[:, 0] + 1) % 3  # seat 0 never moves as it did
        bare, wrong = league.ledger.record_games(training, [
            GameResult("pong", played.players, played.seed, played.scores, played.outcome, played.length, False),
            GameResult("pong", played.players, played.seed, played.scores, played.outcome, played.length, False,
                       actions=encode_actions(tampered)),
        ])
    code, _, err = run(capsys, home, "--game", str(bare))
    assert code == 2 and "stored without its actions" in err and err.count("\n") == 1
    out = tmp_path / "wrong.mp4"
    code, _, err = run(capsys, home, "--game", str(wrong), "--size", "64x32", "--out", str(out))
    assert code == 2 and "no longer plays as it was recorded" in err and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == [], "the rejected replay left no file, partial or whole"


@pytest.mark.slow
def test_nothing_but_the_tool_reaches_the_terminal(home, tmp_path):
    """pygame's audio start-up (ALSA errors) and its banner, ffmpeg's chatter: none of it may show."""
    env = {"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "TERM": "dumb", "HOME": str(tmp_path)}
    out = tmp_path / "quiet.mp4"
    proc = subprocess.run([sys.executable, "-m", "selfplay_cli", "record", "--ckpt", "ep10", "--max-steps", "10",
                           "--size", "64x32", "--out", str(out), "--home", str(home)],
                          capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    assert proc.stdout.startswith(str(out)) and out.exists()


# ---------------------------------------------------------------------------------------------------------------
def test_memory_does_not_grow_with_the_length_of_the_game(tmp_path):
    spec = get_env("pong")
    players = [ScriptedPolicy("pong", "cpu"), ScriptedPolicy("pong", "random", seed=1)]
    settings = VideoSettings(size=(64, 32), hold=0)

    def peak(steps: int) -> int:
        tracemalloc.start()
        try:
            rec = record_game(spec, players, Game(0, (0, 1)), tmp_path / f"{steps}.mp4", settings,
                              stop_when=stop_rule(spec, {}, max_steps=steps))
            assert rec.frames == steps + 1
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    short, long = peak(60), peak(360)
    frame = 400 * 800 * 3
    assert long - short < frame, f"300 more frames cost {(long - short) / 1e6:.1f} MB of peak memory"


def test_the_runner_returns_actions_that_replay_every_game_exactly():
    """Games of a batch that reuses its slots (12 games on 3 slots), each replayed alone from its actions."""
    cpu, rnd = ScriptedPolicy("pong", "cpu"), ScriptedPolicy("pong", "random", seed=5)
    options = {"points_to_win": 2}
    results = play("pong", [cpu, rnd], rounds(Rules(), (0, 1), 6), parallel=3, env_options=options, record_actions=True)
    for r in results:
        actions = decode_actions(r.actions, 2, r.length)
        (again,) = play("pong", replay_policies(r.players, "pong", actions), [Game(r.seed, (0, 1))], parallel=1,
                        env_options=options)
        assert (again.scores, again.length, again.players) == (r.scores, r.length, r.players)
    assert play("pong", [cpu, rnd], rounds(Rules(), (0, 1), 1), env_options=options)[0].actions is None
    short = replay_policies(("cpu", "random"), "pong", decode_actions(results[0].actions, 2)[:10])
    with pytest.raises(ReplayError, match="ran out after 10 steps"):
        play("pong", short, [Game(results[0].seed, (0, 1))], parallel=1, env_options=options)
    with pytest.raises(MarlError, match="unknown format"):
        decode_actions(b"not actions", 2)


@pytest.mark.parametrize("top", [0, 2, 3, 15, 255, 256, 70_000])
def test_actions_round_trip_in_as_few_bits_as_they_need(top):
    rng = np.random.default_rng(top)
    for steps, seats in ((0, 2), (1, 1), (4_501, 2), (33, 3)):
        actions = rng.integers(0, top + 1, (steps, seats))
        assert np.array_equal(decode_actions(encode_actions(actions), seats, steps), actions)


def test_pong_actions_pack_four_to_a_byte_and_their_length_is_checked():
    pong_game = np.random.default_rng(0).integers(0, 3, (4_000, 2))
    assert len(encode_actions(pong_game)) < 4_000 * 2 / 4 + 64, "even random actions take 2 bits each"
    with pytest.raises(MarlError, match="cover 4000 steps, the game lasted 10"):
        decode_actions(encode_actions(pong_game), 2, 10)


def test_frames_of_odd_size_make_an_mp4_one_pixel_larger(tmp_path):
    """A game's own render() may draw any size (connect four: 891 x 774); yuv420p needs even sides, so the frame is
    padded by one black row or column rather than failing the recording."""
    from selfplay_cli.record.video import VideoWriter

    path = tmp_path / "odd.mp4"
    frame = np.full((35, 51, 3), 200, dtype=np.uint8)
    with VideoWriter(path, fps=10) as video:
        for _ in range(5):
            video.write(frame)
    frames = np.stack(list(iio.imiter(path)))
    assert frames.shape == (5, 36, 52, 3)
    assert abs(int(frames[:, :35, :51].mean()) - 200) <= 3 and frames[:, 35:, :].max() < 20
