"""``relight demo`` end to end at the smallest size: the three steps run through the
library, write what the README promises, and a second run resumes."""
import json
import os

from relight.cli import main


def test_demo_runs_end_to_end_and_resumes(tmp_path, capsys):
    out = tmp_path / "demo"
    argv = ["demo", "--out", str(out), "--count", "2", "--res", "16", "--spp", "4"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "Table 1" in text and "figure3.png" in text
    with open(out / "evaluation" / "predictions.json") as f:
        preds = json.load(f)["predictions"]
    assert sorted(p["id"] for p in preds) == ["000000", "000001"]
    summary = json.loads((out / "compare" / "summary.json").read_text())
    assert summary["n"] == 2 and (out / "compare" / "figure3.png").stat().st_size > 0
    first = (out / "dataset" / "images" / "000000.png").stat().st_mtime_ns
    assert main(argv) == 0          # resumes: the dataset is complete, the reports are rewritten
    assert (out / "dataset" / "images" / "000000.png").stat().st_mtime_ns == first
    assert len(os.listdir(out / "dataset" / "images")) == 2
