"""Issue 13, item 10: ``tunespec run`` has an example configuration that runs.

The example is shipped (``resources/examples/run.toml``), printed by ``tunespec run
--print-example``, and the short example in ``load_config``'s docstring parses.
"""

from __future__ import annotations

import json
import textwrap
import tomllib

import pytest

from tunespec.app.cli import main
from tunespec.app.pipeline.plan import (
    check_config,
    example_config,
    load_config,
    plan_from_config,
)
from tunespec.core.datasets import resource_path
from tunespec.core.errors import InputError


def test_print_example_prints_the_shipped_file(capsys) -> None:
    assert main(["run", "--print-example"]) == 0
    out = capsys.readouterr().out
    assert out == example_config()
    assert out == resource_path("examples", "run.toml").read_text(encoding="utf-8")


def test_example_is_every_section_and_makes_a_plan(tmp_path) -> None:
    cfg = tomllib.loads(example_config())
    assert set(cfg) == {
        "out",
        "scheduler",
        "bench",
        "capture",
        "chart",
        "sample",
        "calibrate",
        "estimate",
        "export",
        "provenance",
    }
    path = tmp_path / "run.toml"
    path.write_text(example_config(), encoding="utf-8")
    plan = plan_from_config(load_config(path))
    assert plan.out_dir == tmp_path / "run"
    assert plan.light == "sim" and plan.camera == "sim"
    assert plan.resolution == (768, 512)
    assert plan.method == "bayes" and plan.exposure == "auto"
    assert str(plan.grid) == "380:730:5" and str(plan.estimation_grid) == "400:700:5"
    assert plan.reference is not None  # the simulated bench's truth: Table 2
    assert plan.scheduler == "threads" and plan.images is False


def test_load_config_docstring_example_parses(tmp_path) -> None:
    doc = load_config.__doc__ or ""
    block = doc.split("A short one::", 1)[1].split("\n\n    Sections:", 1)[0]
    text = textwrap.dedent(block).strip("\n")
    assert tomllib.loads(text)["calibrate"]["method"] == "bayes"
    path = tmp_path / "short.toml"
    path.write_text(text, encoding="utf-8")
    check_config(load_config(path))


def test_run_without_a_configuration_says_how_to_get_one(capsys) -> None:
    assert main(["run"]) == 2
    err = capsys.readouterr().err
    assert "--print-example" in err and "Traceback" not in err


@pytest.mark.slow
def test_the_printed_example_runs(tmp_path, capsys) -> None:
    assert main(["run", "--print-example"]) == 0
    path = tmp_path / "run.toml"
    path.write_text(capsys.readouterr().out, encoding="utf-8")
    assert main(["run", str(path)]) == 0
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["table1_rgb_rms_mean"] < 0.01
    assert summary["table2_delta_e00_mean"] < 2.0
    assert (tmp_path / "run" / "export" / "report.pdf").stat().st_size > 10_000


def test_a_bad_example_value_names_the_key(tmp_path) -> None:
    path = tmp_path / "run.toml"
    path.write_text(example_config().replace("iso = 100", 'iso = "high"'))
    with pytest.raises(InputError, match=r"capture\.iso"):
        plan_from_config(load_config(path))


@pytest.mark.parametrize(
    "value", ['"tcp://host"', '"tcp://host:70000"', '"cluster"', "8786", '"http://h:1"']
)
def test_a_bad_scheduler_is_one_line_naming_the_file_and_key(
    tmp_path, capsys, value
) -> None:
    path = tmp_path / "run.toml"
    path.write_text(f'out = "m"\nscheduler = {value}\n', encoding="utf-8")
    assert main(["run", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert str(path) in err and "scheduler:" in err and "tcp://HOST:8786" in err
    assert not (tmp_path / "m").exists()  # nothing started


@pytest.mark.parametrize("value", [None, "threads", "sync", "tcp://10.1.2.3:8786"])
def test_the_scheduler_reaches_the_plan(tmp_path, value) -> None:
    text = 'out = "m"\n' + ("" if value is None else f'scheduler = "{value}"\n')
    path = tmp_path / "run.toml"
    path.write_text(text + "[export]\nimages = true\n", encoding="utf-8")
    # an address in a file needs the command line's confirmation (issue 24)
    confirm = value if value and "://" in value else None
    plan = plan_from_config(load_config(path), scheduler=confirm)
    assert plan.scheduler == value and plan.images


@pytest.mark.slow
def test_a_run_computes_the_images_on_the_configured_cluster(tmp_path) -> None:
    """``scheduler = "tcp://..."`` with ``[export] images = true``: the sample's
    per-pixel images are computed by the cluster's workers, into export/images/."""
    from distributed import LocalCluster

    with LocalCluster(
        n_workers=1, processes=False, protocol="tcp", dashboard_address=":0"
    ) as cluster:
        path = tmp_path / "run.toml"
        path.write_text(
            f'out = "m"\nscheduler = "{cluster.scheduler_address}"\n'
            '[bench]\nresolution = "512x340"\n'
            "[export]\nreport = false\nimages = true\n",
            encoding="utf-8",
        )
        confirm = ["--scheduler", cluster.scheduler_address]
        assert main(["run", str(path), "-q", *confirm]) == 0
        ran = set(cluster.scheduler.task_prefixes)
    images = tmp_path / "m" / "export" / "images"
    prov = json.loads((images / "provenance.json").read_text())
    assert prov["shape"][0] > 0 and len(prov["channels"]) == 22
    assert (images / "srgb.png").is_file()
    assert ran, "no task reached the cluster"
