"""ParameterValueDistribution files: lazy index → parameter values, and a manifest sweep pointing at one."""

from __future__ import annotations

from pathlib import Path

import pytest

from simcore.errors import BadInput
from simcore.plan import Plan
from simcore.scenario.distribution import load_distribution
from simcore.spec import SimulationRunSpec
from tests.xosc_fixtures import file_header

HEAD = f'<?xml version="1.0"?><OpenSCENARIO>{file_header()}'


def write(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "dist.xosc"
    path.write_text(
        f'{HEAD}<ParameterValueDistribution><ScenarioFile filepath="s.xosc"/>{body}</ParameterValueDistribution></OpenSCENARIO>'
    )
    return path


DETERMINISTIC = """<Deterministic>
  <DeterministicMultiParameterDistribution><ValueSetDistribution>
    <ParameterValueSet><ParameterAssignment parameterRef="A" value="a1"/><ParameterAssignment parameterRef="B" value="b1"/></ParameterValueSet>
    <ParameterValueSet><ParameterAssignment parameterRef="A" value="a2"/></ParameterValueSet>
  </ValueSetDistribution></DeterministicMultiParameterDistribution>
  <DeterministicSingleParameterDistribution parameterName="S"><DistributionSet><Element value="x"/><Element value="y"/></DistributionSet></DeterministicSingleParameterDistribution>
  <DeterministicSingleParameterDistribution parameterName="R"><DistributionRange stepWidth="0.5"><Range lowerLimit="1" upperLimit="2"/></DistributionRange></DeterministicSingleParameterDistribution>
</Deterministic>"""


def test_deterministic_cross_product_last_fastest(tmp_path: Path) -> None:
    d = load_distribution(write(tmp_path, DETERMINISTIC))
    assert len(d) == 2 * 2 * 3
    assert d[0] == {"A": "a1", "B": "b1", "S": "x", "R": "1.0"}
    assert d[1]["R"] == "1.5" and d[2]["R"] == "2.0" and d[3] == {"A": "a1", "B": "b1", "S": "y", "R": "1.0"}
    assert d[11] == {"A": "a2", "S": "y", "R": "2.0"}
    assert d.scenario_file == (tmp_path / "s.xosc").resolve()
    with pytest.raises(IndexError):
        d[12]


STOCHASTIC = """<Stochastic numberOfTestRuns="200" randomSeed="7">
  <StochasticDistribution parameterName="U"><UniformDistribution><Range lowerLimit="10" upperLimit="20"/></UniformDistribution></StochasticDistribution>
  <StochasticDistribution parameterName="N"><NormalDistribution expectedValue="5" variance="4"><Range lowerLimit="0" upperLimit="10"/></NormalDistribution></StochasticDistribution>
  <StochasticDistribution parameterName="P"><PoissonDistribution expectedValue="3"/></StochasticDistribution>
  <StochasticDistribution parameterName="C"><ProbabilityDistributionSet><Element value="red" weight="1"/><Element value="blue" weight="3"/></ProbabilityDistributionSet></StochasticDistribution>
  <StochasticDistribution parameterName="H"><Histogram><Bin weight="1"><Range lowerLimit="0" upperLimit="1"/></Bin><Bin weight="1"><Range lowerLimit="5" upperLimit="6"/></Bin></Histogram></StochasticDistribution>
</Stochastic>"""


def test_stochastic_draws_depend_on_seed_and_index_only(tmp_path: Path) -> None:
    d = load_distribution(write(tmp_path, STOCHASTIC))
    assert len(d) == 200
    draws = [d[k] for k in range(200)]
    assert draws[17] == load_distribution(write(tmp_path, STOCHASTIC))[17]  # any index alone, repeatably
    assert len({x["U"] for x in draws}) > 150  # they differ between indexes
    assert all(10 <= float(x["U"]) <= 20 and 0 <= float(x["N"]) <= 10 for x in draws)
    assert all(int(x["P"]) >= 0 for x in draws)
    assert 100 < sum(x["C"] == "blue" for x in draws) < 190
    assert all(0 <= float(x["H"]) <= 1 or 5 <= float(x["H"]) <= 6 for x in draws)
    mean_n = sum(float(x["N"]) for x in draws) / 200
    assert 4.4 < mean_n < 5.6


def test_bad_distribution_names_the_file(tmp_path: Path) -> None:
    with pytest.raises(BadInput, match="Deterministic> or <Stochastic"):
        load_distribution(write(tmp_path, ""))
    bad = DETERMINISTIC.replace('stepWidth="0.5"', 'stepWidth="-1"')
    with pytest.raises(BadInput, match=r"dist\.xosc"):
        load_distribution(write(tmp_path, bad))


def test_sweep_points_at_a_distribution(tmp_path: Path) -> None:
    path = write(tmp_path, DETERMINISTIC)
    spec = SimulationRunSpec.model_validate(
        {
            "scenarios": [{"name": "a", "openscenario": "a.xosc"}, {"name": "b", "openscenario": "b.xosc"}],
            "sweep": {"matrix": {"M": [1, 2]}, "distribution": str(path), "repetitions": 2},
        }
    )
    plan = Plan(spec)
    assert len(plan) == 2 * (2 * 12) * 2
    point = plan[2 * 13 + 1]  # scenario a, matrix M=2, distribution permutation 1, repetition 1
    assert point.scenario.name == "a" and point.repetition == 1
    assert point.sweep_values == {"M": 2, "A": "a1", "B": "b1", "S": "x", "R": "1.5"}
    assert plan[len(plan) - 1].scenario.name == "b"


def test_manifest_distribution_path_is_relative_to_the_manifest(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from simcore.manifest import load_manifest

    folder = tmp_path / "runs"
    folder.mkdir()
    write(folder, DETERMINISTIC)
    manifest = folder / "sweep.yaml"
    manifest.write_text(
        "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\nmetadata: {name: sweep}\n"
        "spec:\n  scenarios: [{name: a, openscenario: a.xosc}]\n  sweep: {distribution: dist.xosc}\n"
    )
    monkeypatch.chdir(tmp_path)  # not the manifest's folder
    run = load_manifest(manifest)
    assert run.spec.sweep.distribution == str(folder / "dist.xosc")
    assert len(Plan(run.spec)) == 12
