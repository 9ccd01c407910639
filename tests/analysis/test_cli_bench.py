import json

import pytest

from phantomtouch.cli import main


def test_bench_accuracy_prints_json_and_writes_the_plot(tmp_path, capsys) -> None:
    pytest.importorskip("matplotlib")
    plot = tmp_path / "accuracy.png"
    argv = ["bench", "accuracy", "--frames", "1", "32", "--stroke", "stop-and-go"]
    assert main([*argv, "--repeats", "1", "--json", "--plot", str(plot)]) == 0
    report = json.loads(capsys.readouterr().out)
    assert [r["setting"] for r in report["rows"]] == ["1 (per frame)", "32 ramp", "32 hold"]
    assert report["strokes"] == ["stop-and-go"]
    assert report["recommended"] in {"1 (per frame)", "32 ramp"}
    assert plot.read_bytes()[:4] == b"\x89PNG"


def test_bench_accuracy_prints_a_table(capsys) -> None:
    argv = ["bench", "accuracy", "--frames", "8", "--stroke", "exp2-curved", "--repeats", "1"]
    assert main(argv) == 0
    captured = capsys.readouterr()
    out = captured.out
    assert "1 (per frame)" in out and "8 ramp" in out and "recommended default" in out
    # progress on stderr: three renders (per frame, 8 ramp, 8 hold) of one stroke
    assert "bench accuracy" in captured.err and "3/3" in captured.err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--stroke", "nope"], "--stroke 'nope'"),
        (["--frames", "0"], "--frames [0]"),
    ],
)
def test_bench_accuracy_refuses_bad_options(argv: list[str], message: str, capsys) -> None:
    assert main(["bench", "accuracy", *argv]) == 2
    assert message in capsys.readouterr().err
