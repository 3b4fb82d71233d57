"""datmo tune's pieces: the space and its refusals, the samples, the rungs, the objective's names; and, on the
hall (slow), a tune interrupted and resumed, its best.toml scored again by datmo run + datmo evaluate, the
same tune on a local Dask cluster, and a detuned start brought back."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from datmo_cli.base.errors import ConfigError, InputError
from datmo_cli.passes.config import DatmoConfig
from datmo_cli.tune import TuneInterrupted, run_tune
from datmo_cli.tune.objective import higher_is_better, log_metrics, parse_constraint
from datmo_cli.tune.search import rungs, settings
from datmo_cli.tune.space import load_space, samples
from datmo_cli.tune.trial import LogInput, log_input

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parent.parent
HALL = ROOT / "sample_logs" / "hall.mcap"


def space(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "space.toml"
    path.write_text(text)
    return path


def test_a_space_reads_ranges_and_choices(tmp_path):
    dims = load_space(
        space(
            tmp_path,
            "[track]\nperson_maintain = [0.05, 0.3]\nconfirm_hits = [2, 6]\n"
            "delete_after = { range = [0.3, 3.0], log = true }\n"
            '[features]\nleg_model = ["default", "paper"]\n',
        )
    )
    by_key = {d.key: d for d in dims}
    assert list(by_key) == ["features.leg_model", "track.person_maintain", "track.confirm_hits", "track.delete_after"]
    assert by_key["track.confirm_hits"].integer and not by_key["track.person_maintain"].integer
    assert by_key["track.delete_after"].log
    assert by_key["features.leg_model"].choices == ("default", "paper")


@pytest.mark.parametrize(
    ("text", "said"),
    [
        ("[track]\nperson_maintian = [0.05, 0.3]\n", "track.person_maintian: unknown parameter"),
        ("[track]\nperson_maintain = [0.05, 3.0]\n", "track.person_maintain: must be at most 1, got 3"),
        ("[features]\nleg_model = []\n", "features.leg_model: an empty list of choices"),
        ("[track]\nperson_maintain = [0.3, 0.05]\n", "track.person_maintain: a range's low end must be below"),
        ('[features]\nleg_model = ["default", "papper"]\n', "features.leg_model: papper: no such leg model"),
        ("[track]\nconfirm_hits = [2.5, 6]\n", "track.confirm_hits: expected int"),
    ],
)
def test_a_bad_space_is_refused_naming_the_file_and_key(tmp_path, text, said):
    path = space(tmp_path, text)
    with pytest.raises(ConfigError) as err:
        load_space(path)
    message = str(err.value)
    assert message.startswith(f"{path}: ") and said in message and "\n" not in message


def test_the_samples_are_the_same_for_a_seed_and_stay_in_the_space(tmp_path):
    dims = load_space(space(tmp_path, "[track]\nperson_maintain = [0.05, 0.3]\nconfirm_hits = [2, 6]\n"))
    a, b, other = samples(dims, 12, 7), samples(dims, 12, 7), samples(dims, 12, 8)
    assert a == b and a != other and len(a) == 12
    assert all(0.05 <= s["track.person_maintain"] <= 0.3 for s in a)
    assert all(isinstance(s["track.confirm_hits"], int) and 2 <= s["track.confirm_hits"] <= 6 for s in a)
    assert {s["track.confirm_hits"] for s in a} == {2, 3, 4, 5, 6}  # quasi-random: every value is met


def test_trial_0_is_the_start_and_a_setting_the_config_refuses_is_a_refused_trial(tmp_path):
    dims = load_space(space(tmp_path, "[track]\nconfirm_hits = [2, 8]\n"))  # confirm_window stays 5
    trials = settings(DatmoConfig(), dims, 16, 0)
    assert trials[0].values == {"track.confirm_hits": 3} and trials[0].config == DatmoConfig()
    refused = [t for t in trials if t.config is None]
    assert refused and all(t.values["track.confirm_hits"] > 5 for t in refused)
    assert all("confirm_window" in (t.refused or "") for t in refused)


def _log(seconds: float) -> LogInput:
    return LogInput("x.mcap", None, "0" * 64, int(seconds * 5), seconds)


def test_successive_halving_scores_a_prefix_first_when_the_logs_are_long_enough():
    assert rungs(24, [_log(59.8)]) == [1 / 3, 1.0]
    assert rungs(24, [_log(600.0)]) == [1 / 9, 1 / 3, 1.0]
    assert rungs(2, [_log(600.0)]) == [1.0]  # too few trials to halve
    assert rungs(24, [_log(600.0), _log(20.0)]) == [1.0]  # the shortest log's prefix would be under 15 s


def test_the_objective_names_are_evaluates_figures():
    scores = {
        "all": {"mota": 0.8, "hota": None, "num_false_positives": 6, "num_switches": 2},
        "person": {"mota": 0.7, "num_false_positives": 3},
    }
    m = log_metrics(scores, 60.0)
    assert m["mota"] == 0.8 and m["hota"] is None and m["people_mota"] == 0.7 and m["circle_mota"] is None
    assert math.isclose(m["false_people_s"], 0.05) and math.isclose(m["false_positives_s"], 0.1)
    assert higher_is_better("people_idf1") and not higher_is_better("motp") and not higher_is_better("false_people_s")
    c = parse_constraint("false_people_s=1", True)
    assert c.met(0.5) and not c.met(1.5) and not c.met(None)
    for bad in ("false_people_s", "false_people_s=x", "fals_people_s=1"):
        with pytest.raises(ConfigError, match="^--max "):
            parse_constraint(bad, True)


def test_a_log_without_ground_truth_is_refused_naming_it(tmp_path):
    log = ROOT / "sample_logs" / "csail-excerpt.mcap"
    with pytest.raises(InputError, match=r"csail-excerpt\.mcap: no ground truth.*csail-excerpt\.gt\.csv"):
        log_input(log)
    assert log_input(HALL).gt_csv is None


# ------------------------------------------------------------------------------- tunes on the hall (slow)

SPACE = "[track]\nperson_maintain = [0.05, 0.3]\nconfirm_hits = [2, 5]\n"


def _trials(folder: Path) -> list[dict]:
    import pyarrow.parquet as pq

    return pq.read_table(folder / "trials.parquet").to_pylist()


@pytest.fixture(scope="module")
def tuned(tmp_path_factory):
    """A tune of 4 trials on the hall, interrupted (Ctrl-C) after its second evaluation, then run again to the
    end, then once more: (folder, the three runs' results; the first is None)."""
    folder = tmp_path_factory.mktemp("tune")
    path = space(folder, SPACE)
    out = folder / "out"
    seen = []

    def interrupt(done: int, total: int, what: str) -> None:
        seen.append(done)
        if done == 2:
            raise KeyboardInterrupt

    with pytest.raises(TuneInterrupted, match="2 evaluations done"):
        run_tune([HALL], path, out, trials=4, jobs=1, progress=interrupt)
    resumed = run_tune([HALL], path, out, trials=4, jobs=1)
    again = run_tune([HALL], path, out, trials=4, jobs=1)
    return out, path, resumed, again


@pytest.mark.slow
def test_an_interrupted_tune_continues_without_redoing_finished_evaluations(tuned):
    out, _, resumed, again = tuned
    assert resumed.reused == 2 and resumed.ran >= 4  # 4 trials on the first third, the best 2 on the whole log
    assert again.ran == 0 and again.reused == resumed.ran + resumed.reused
    assert again.best.index == resumed.best.index and again.best_score.value == resumed.best_score.value
    rows = _trials(out)
    assert [r["trial"] for r in rows] == [0, 1, 2, 3] and rows[0]["start"]
    assert {"track.person_maintain", "track.confirm_hits", "hota", "hall.mcap:mota", "seconds"} <= set(rows[0])


@pytest.mark.slow
def test_best_toml_gives_the_reported_objective_through_run_and_evaluate(tuned, tmp_path):
    import json

    from click.testing import CliRunner

    from datmo_cli.cli import cli

    out, _, resumed, _ = tuned
    best = (out / "best.toml").read_text()
    assert f"hota = {resumed.best_score.value!r}" in best
    r = CliRunner().invoke(cli, ["run", str(HALL), "-o", str(tmp_path), "--config", str(out / "best.toml"), "-q"])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(cli, ["evaluate", str(tmp_path / "hall.mcap"), "--format", "json"])
    assert r.exit_code == 0, r.output
    hota = json.loads(r.output[r.output.index("{") :])["scores"]["all"]["hota"]
    assert abs(hota - resumed.best_score.value) <= 1e-9


@pytest.mark.slow
def test_a_local_dask_cluster_gives_the_same_trials_and_best(tuned, tmp_path):
    pytest.importorskip("distributed")
    out, path, resumed, _ = tuned
    dask = run_tune([HALL], path, tmp_path / "dask", trials=4, scheduler="local:2")
    assert dask.reused == 0 and dask.best.index == resumed.best.index
    local, remote = _trials(out), _trials(tmp_path / "dask")
    for a, b in zip(local, remote, strict=True):
        assert a["track.person_maintain"] == b["track.person_maintain"] and a["rung"] == b["rung"]
        assert a["hota"] == pytest.approx(b["hota"], abs=1e-12)


@pytest.mark.slow
def test_a_detuned_start_is_brought_back_to_the_defaults_mota(tmp_path):
    from datmo_cli.evaluate.files import score_file
    from datmo_cli.passes.pipeline import process_file

    process_file(HALL, tmp_path / "default.mcap")
    default_mota = score_file(tmp_path / "default.mcap")["scores"]["all"]["mota"]
    start = DatmoConfig().replace(track={"confirm_hits": 8, "confirm_window": 8})
    path = space(tmp_path, "[track]\nconfirm_hits = [2, 8]\nconfirm_window = [5, 10]\ndelete_after = [0.4, 2.0]\n")
    result = run_tune([HALL], path, tmp_path / "out", config=start, objective="mota", trials=8, jobs=2)
    assert result.start_score.value < default_mota - 0.01  # the start is detuned
    assert result.best_score.value >= default_mota


@pytest.mark.slow
def test_a_log_with_its_ground_truth_in_a_csv_beside_it_is_tuned_as_evaluate_gt_scores_it(tmp_path):
    from click.testing import CliRunner

    from datmo_cli.cli import cli
    from datmo_cli.evaluate.files import score_file
    from datmo_cli.logs import mcapio

    contents = mcapio.read_log(HALL, topics=None)
    log = tmp_path / "hall.mcap"  # the hall without its ground-truth channel
    with mcapio.LogWriter(log) as w:
        for ch in contents.channels.values():
            if ch.topic != mcapio.TOPIC_GROUND_TRUTH:
                w.channel(ch.topic, ch.msgtype, schema_text=ch.schema_data.decode(), metadata=ch.metadata)
                w.write_many(ch.topic, ch.msgtype, *contents.messages[ch.topic])
    r = CliRunner().invoke(cli, ["export", str(HALL), "--ground-truth", "-o", str(tmp_path / "hall.gt.csv")])
    assert r.exit_code == 0, r.output
    assert log_input(log).gt_csv == str(tmp_path / "hall.gt.csv")
    path = space(tmp_path, "[track]\nperson_maintain = [0.05, 0.3]\n")
    result = run_tune([log], path, tmp_path / "out", objective="mota", trials=3, jobs=1)
    assert result.fractions == [1 / 3, 1.0] and result.best_score.error is None
    whole = result.best_score.per_log["hall.mcap"]["num_objects"]
    prefix = [result.scores[t.index].per_log["hall.mcap"]["num_objects"] for t in result.trials if t.rung == 0]
    assert prefix and all(abs(n - whole / 3) < 0.05 * whole for n in prefix)  # the CSV cut with the scans
    process_out = tmp_path / "check.mcap"
    from datmo_cli.passes.pipeline import process_file

    process_file(log, process_out, config=result.best.config)
    mota = score_file(process_out, gt_csv=tmp_path / "hall.gt.csv")["scores"]["all"]["mota"]
    assert abs(mota - result.best_score.value) <= 1e-9


def test_a_trial_missing_a_constraint_ranks_after_those_meeting_it():
    from datmo_cli.tune.search import Goal, Score, Trial, rank_key

    goal = Goal("mota", True, (parse_constraint("false_people_s=1", True),))
    trials = [Trial(i, {}, DatmoConfig()) for i in range(4)]
    scores = [
        Score(0.95, {"false_people_s": 2.0}, False),  # the highest MOTA, too many false people
        Score(0.80, {"false_people_s": 0.5}, True),
        Score(0.85, {"false_people_s": 0.9}, True),
        Score(error="refused"),
    ]
    order = sorted(range(4), key=lambda i: rank_key(trials[i], scores[i], goal))
    assert order == [2, 1, 0, 3]
    lower = Goal("motp", False)
    assert rank_key(trials[0], Score(0.1, feasible=True), lower) < rank_key(trials[1], Score(0.2, feasible=True), lower)


@pytest.mark.slow
def test_cv_scores_each_folds_best_on_the_log_left_out(tmp_path):
    corridor = ROOT / "sample_logs" / "corridor.mcap"
    result = run_tune([HALL, corridor], space(tmp_path, SPACE), tmp_path / "out", trials=3, jobs=2, cv=True)
    assert [f.held_out for f in result.folds] == ["hall.mcap", "corridor.mcap"]
    from datmo_cli.evaluate.files import score_file
    from datmo_cli.passes.pipeline import process_file

    fold = result.folds[0]  # tuned on the corridor alone, scored on the hall
    best = next(t for t in result.trials if t.index == fold.best)
    process_file(HALL, tmp_path / "held.mcap", config=best.config)
    held = score_file(tmp_path / "held.mcap")["scores"]["all"]["hota"]
    assert fold.held_out_value is not None and abs(held - fold.held_out_value) <= 1e-9
    assert fold.tuned is not None
    best_toml = (tmp_path / "out" / "best.toml").read_text()
    assert best_toml.count("# cv: tuned without") == 2
