"""Variant sets as data (`bench.matrix`): the matrix file format, its transforms, its errors, and every shipped set
and experiment file read, validated and runnable together."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from frictionbench.bench.cli import parse_variants
from frictionbench.bench.matrix import DEFAULT, MATRICES, SUITE_DEFAULTS, load_matrix, set_names, variant_set
from frictionbench.bench.runner import distinct_variants, guard_resources, truth_config
from frictionbench.scenarios.errors import ScenarioError
from frictionbench.scenarios.load import scenario_from_dict
from frictionbench.scenarios.suites import load_suite
from frictionbench.solvers.registry import get_solver

from scenes import EXPERIMENTS, block_drop


def _matrix(tmp_path: Path, text: str, name: str = "m.toml") -> list:
    path = tmp_path / name
    path.write_text(text)
    return list(load_matrix(path).variants)


def test_an_entry_with_axes_is_their_product_labelled_by_each_points_tag_on_its_preset(tmp_path):
    variants = _matrix(tmp_path, """
[[variant]]
solver = "licrom"
label = "r{r}-{scheme}"
preset = "licrom"
params = { points = 64 }
axis = [{ name = "r", param = "r", values = [8, 16] },
        { name = "scheme", values = [{ tag = "n" }, { tag = "pg", params = { scheme = "projected_gradient" } }] }]
""")
    assert [v.label for v in variants] == ["r8-n", "r8-pg", "r16-n", "r16-pg"]
    assert [(v.params["r"], v.params["scheme"]) for v in variants] == [
        (8, "newton"), (8, "projected_gradient"), (16, "newton"), (16, "projected_gradient")]
    preset = variant_set("licrom")[0].params  # the preset's other parameters, the entry's points on top
    assert all(v.params | {"r": 0, "scheme": 0, "points": 0} == preset | {"r": 0, "scheme": 0, "points": 0}
               and v.params["points"] == 64 for v in variants)
    for v in variants:  # every point a valid solver
        get_solver(v.solver)(device="cpu", **v.params)


def test_transforms_ladder_lag_retune_and_other_mesh_compose_in_order(tmp_path):
    variants = _matrix(tmp_path, """
[[base]]
solver = "pod"
label = "p"
params = { r = 8 }

[[variant]]
from = "p"
then = [{ lag = ["scene", "fixed-point"] }, { ladder = { levels = [0, 1], integrators = ["bdf2"] } },
        { other_mesh = "beside" }]

[[variant]]
from = "p"
label = "q"
then = [{ retune = { params = { tol = 1.0e-3 }, suffix = "-loose" } }]
""")
    assert [v.label for v in variants] == [
        "p-bdf2", "p-bdf2-remesh", "p-bdf2-dt/2", "p-bdf2-dt/2-remesh",
        "p-fixed-point-bdf2", "p-fixed-point-bdf2-remesh", "p-fixed-point-bdf2-dt/2", "p-fixed-point-bdf2-dt/2-remesh",
        "q-loose"]  # the base `p` defines, it does not run
    sc = scenario_from_dict(block_drop() | {"name": "s"})
    own = [v for v in variants[:-1] if not v.remesh]
    assert [v.scenario(sc).contact.lag for v in own] == ["start", "start", "fixed-point", "fixed-point"]
    assert [v.dt_scale for v in own] == [1.0, 0.5] * 2 and all(v.scenario(sc).time.integrator == "bdf2" for v in own)
    assert [v.model for v in own] == ["p", "p", "p-fixed-point", "p-fixed-point"]  # a curve's levels on one model
    for v, other in zip(variants[0:8:2], variants[1:8:2]):
        assert other.remesh == "alt" and other.remesh_of == v.label and not other.tags and other.params == v.params
    loose = variants[-1]  # settings that train nothing: the same model
    assert loose.params == {"r": 8, "tol": 1e-3} and loose.model == "q"


def test_an_include_puts_a_shipped_set_or_a_file_there_through_its_transforms(tmp_path):
    _matrix(tmp_path, '[[variant]]\nsolver = "pod"\nlabel = "a"\nparams = { r = 4 }\n', "inner.toml")
    variants = _matrix(tmp_path, """
[[variant]]
include = "bdf2"

[[variant]]
include = "inner.toml"
then = [{ other_mesh = "only" }]
""")
    assert variants[0] == variant_set("bdf2")[0]
    assert [(v.label, v.remesh) for v in variants[1:]] == [("a-remesh", "alt")]


@pytest.mark.parametrize(("text", "field", "reason"), [
    ("[[variant]]\nsolver = 'full'\nlabl = 'x'\n", "variant[0].labl", "did you mean 'label'"),
    ("[[variant]]\nsolver = 'nope'\n", "variant[0].solver", "unknown solver"),
    ("[[variant]]\nsolver = 'full'\nparams = { r = 4 }\n", "variant[0].params", r"unknown parameter\(s\)"),
    ("[[variant]]\nsolver = 'licrom'\npreset = 'fast'\n", "variant[0].preset", "unknown preset"),
    ("[[variant]]\nfrom = 'x'\n", "variant[0].from", "not defined above"),
    ("[[variant]]\nsolver = 'full'\nthen = [{ lag = 'late' }]\n", "variant[0].then[0].lag", "expected 'scene'"),
    ("[[variant]]\nsolver = 'full'\nthen = [{ ladder = { levels = [1, 1] } }]\n", "variant[0].then[0].ladder",
     "distinct integers"),
    ("[[variant]]\nsolver = 'full'\nthen = [{ twice = 1 }]\n", "variant[0].then[0].twice", "unknown key"),
    ("[[variant]]\nsolver = 'full'\nlabel = 'a{b}'\n", "variant[0].label", "no axis named"),
    ("[[variant]]\nsolver = 'full'\naxis = [{ name = 'a', values = [] }]\n", "variant[0].axis[0]", "non-empty"),
    ("[[variant]]\ninclude = 'bdf2'\nlabel = 'x'\n", "variant[0]", "no other key"),
    ("[[variant]\n", "m.toml", "cannot read"),
    ("[[variant]]\nsolver = 'pod'\nparams = { hessian = 'single' }\n", "variant[0].params", "experimental"),
    ("[[variant]]\nsolver = 'pod'\nexperimental = { r = 4 }\n", "variant[0].experimental",
     "not an experimental parameter"),
    ("[[variant]]\nsolver = 'pod'\nthen = [{ retune = { params = { iterations = 3 } } }]\n",
     "variant[0].then[0].retune.params", "experimental"),
])
def test_a_bad_matrix_file_is_refused_naming_the_field(tmp_path, text, field, reason):
    with pytest.raises(ScenarioError, match=reason) as err:
        _matrix(tmp_path, text)
    assert field in err.value.field


def test_an_experimental_parameter_is_set_in_its_own_table_and_runs_as_any_other(tmp_path):
    (v,) = _matrix(tmp_path, """
[[variant]]
solver = "pod"
label = "p"
params = { r = 4 }
experimental = { hessian = "single" }
then = [{ retune = { experimental = { hessian_refresh = "step" }, suffix = "-step" } }]
""")
    assert v.params == {"r": 4, "hessian": "single", "hessian_refresh": "step"} and v.label == "p-step"
    from frictionbench.solvers.registry import get_solver

    pod = get_solver("pod")
    assert {"hessian", "hessian_refresh"} <= set(pod.experimental) and not set(pod.experimental) & set(pod.parameters)
    assert pod(**v.params).params["hessian_refresh"] == "step"  # the solver takes it as it takes its parameters


@pytest.mark.parametrize("path", [*sorted(MATRICES.glob("*.toml")), *sorted(EXPERIMENTS.glob("*.toml"))],
                         ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_every_shipped_set_and_experiment_file_reads_with_distinct_runs_that_pass_the_guard_on_quick(path):
    if path == MATRICES / "presets.toml":
        assert "presets" not in set_names()
        return
    matrix = load_matrix(path)
    assert matrix.variants and matrix.description and matrix.name == path.stem
    assert distinct_variants(matrix.variants) == list(matrix.variants)  # no two runs under one name
    quick = load_suite("quick")
    guard_resources(quick, list(matrix.variants), truth=truth_config(quick))


def test_the_defaults_name_shipped_sets_and_no_core_module_names_an_experiment():
    assert set(DEFAULT.split(",")) <= set(set_names())
    assert {s for d in SUITE_DEFAULTS.values() for s in d.split(",")} <= set(set_names())
    root = Path(__file__).resolve().parents[1]
    core = [p for d in ("bench", "analysis", "solvers", "scenarios", "reports") for p in (root / d).rglob("*.py")]
    for name in (p.stem for p in EXPERIMENTS.glob("*.toml")):
        assert name not in set_names()
        assert not [p for p in core if f'"{name}"' in p.read_text()], name


def test_run_takes_a_matrix_file_in_place_of_the_default_sets(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text('[[variant]]\nsolver = "full"\nlabel = "loose"\nparams = { tol = 1.0e-3 }\n')
    assert [v.label for v in parse_variants(None, matrices=[str(path)])] == ["loose"]
    assert [v.label for v in parse_variants("bdf2", matrices=[str(path)])] == ["bdf2", "loose"]
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "frictionbench.bench.cli", "run", "--suite", "verify", "--only",
                           "verify/block_fall", "--matrix", str(path), "--no-truth", "--no-report", "--out", str(out)],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    import pandas as pd

    rows = pd.read_csv(out / "results.csv")
    assert set(rows["variant"]) == {"reference", "loose"} and rows["status"].eq("ok").all()
    bad = subprocess.run([sys.executable, "-m", "frictionbench.bench.cli", "run", "--suite", "verify", "--solvers",
                          "pod-fast", "--out", str(tmp_path / "x")], capture_output=True, text=True)
    assert bad.returncode != 0 and "--solvers = 'pod-fast'" in bad.stderr and "--matrix" in bad.stderr


def test_the_matrix_file_example_of_the_docs_reads(tmp_path):
    """docs/variants.md's example matrix file is one the loader reads: two ranks, each a curve of two levels."""
    doc = (Path(__file__).resolve().parents[1] / "docs" / "variants.md").read_text()
    example = doc.split("```toml\n", 1)[1].split("```", 1)[0]
    variants = _matrix(tmp_path, example)
    assert [v.label for v in variants] == ["affine-r24-cub60-bdf2", "affine-r24-cub60-bdf2-dt/2",
                                           "affine-r48-cub60-bdf2", "affine-r48-cub60-bdf2-dt/2"]
