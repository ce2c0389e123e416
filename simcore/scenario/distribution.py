"""OpenSCENARIO ParameterValueDistribution files (1.0–1.3): an index → parameter values, computed lazily.

Deterministic: single-parameter distributions (DistributionSet, DistributionRange) and multi-parameter value
sets (ValueSetDistribution) combine as a cross product in file order, the last one fastest (as a sweep
matrix). Stochastic: `numberOfTestRuns` draws; the draw of index k depends only on the seed (the file's
`randomSeed`, else the one given) and k, so any index is computed alone, on any machine.
"""

from __future__ import annotations

import hashlib
import math
import random
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from math import prod
from pathlib import Path

from simcore.errors import BadInput
from simcore.scenario.parameters import ParameterError, resolve

MAX_PERMUTATIONS = 10_000_000


@dataclass(frozen=True)
class _Group:
    """One factor of the cross product: a list of parameter assignments (name → value text)."""

    options: tuple[tuple[tuple[str, str], ...], ...]


@dataclass(frozen=True)
class _Stochastic:
    name: str
    kind: str
    params: tuple[float, ...]
    low: float | None = None
    high: float | None = None
    weighted: tuple[tuple[float, tuple[float, float] | str], ...] = ()


class ParameterDistribution:
    """`len(d)` permutations; `d[k]` the parameter values of permutation k."""

    def __init__(
        self,
        path: Path,
        scenario_file: Path,
        groups: tuple[_Group, ...] = (),
        stochastic: tuple[_Stochastic, ...] = (),
        runs: int = 0,
        seed: int = 0,
    ) -> None:
        self.path = path
        self.scenario_file = scenario_file
        self.groups = groups
        self.stochastic = stochastic
        self.runs = runs
        self.seed = seed

    def __len__(self) -> int:
        if self.stochastic:
            return self.runs
        return prod(len(g.options) for g in self.groups) if self.groups else 0

    def __getitem__(self, k: int) -> dict[str, str]:
        size = len(self)
        if not 0 <= k < size:
            raise IndexError(f"permutation {k} is out of range 0..{size - 1}")
        if self.stochastic:
            return {s.name: _draw(s, self.seed, k) for s in self.stochastic}
        out: dict[str, str] = {}
        digits = []
        for group in reversed(self.groups):
            k, digit = divmod(k, len(group.options))
            digits.append(group.options[digit])
        for assignment in reversed(digits):
            out.update(dict(assignment))
        return out


def _rng(seed: int, k: int, name: str) -> random.Random:
    digest = hashlib.sha256(f"{seed}:{k}:{name}".encode()).digest()
    return random.Random(int.from_bytes(digest[:8], "big"))


def _fmt(value: float) -> str:
    return repr(float(value))


def _draw(s: _Stochastic, seed: int, k: int) -> str:
    rng = _rng(seed, k, s.name)
    for _ in range(1000):  # rejection sampling into the optional range
        if s.kind == "uniform":
            assert s.low is not None and s.high is not None
            value: float = rng.uniform(s.low, s.high)
        elif s.kind == "normal":
            value = rng.gauss(s.params[0], math.sqrt(s.params[1]))
        elif s.kind == "lognormal":
            mean, variance = s.params
            sigma2 = math.log(1 + variance / (mean * mean))
            value = rng.lognormvariate(math.log(mean) - sigma2 / 2, math.sqrt(sigma2))
        elif s.kind == "poisson":
            value = _poisson(rng, s.params[0])
            if (s.low is None or value >= s.low) and (s.high is None or value <= s.high):
                return str(int(value))
            continue
        else:  # histogram or probability set: weighted choice
            choice = _weighted(rng, s.weighted)
            if isinstance(choice, str):
                return choice
            value = rng.uniform(choice[0], choice[1])
        if (s.low is None or value >= s.low) and (s.high is None or value <= s.high):
            return _fmt(value)
    raise BadInput(f"stochastic distribution of {s.name!r}: no draw within its range after 1000 tries")


def _poisson(rng: random.Random, lam: float) -> int:
    """Knuth's method for small means, a rounded normal approximation above 30."""
    if lam > 30:
        return max(round(rng.gauss(lam, math.sqrt(lam))), 0)
    limit, n, p = math.exp(-lam), 0, rng.random()
    while p > limit:
        n += 1
        p *= rng.random()
    return n


def _weighted(
    rng: random.Random, items: tuple[tuple[float, tuple[float, float] | str], ...]
) -> tuple[float, float] | str:
    total = sum(w for w, _ in items)
    pick = rng.uniform(0, total)
    for weight, item in items:
        pick -= weight
        if pick <= 0:
            return item
    return items[-1][1]


def load_distribution(path: str | Path, seed: int = 0) -> ParameterDistribution:
    """Parse a ParameterValueDistribution file (safely); errors name the file and element."""
    from simcore.scenario.xosc_xml import read_xml

    path = Path(path)
    root = read_xml(path, what="ParameterValueDistribution file")
    pvd = root.find("ParameterValueDistribution")
    if pvd is None:
        raise BadInput("no <ParameterValueDistribution>: not a distribution file", file=str(path))
    values: dict[str, bool | int | float | str] = {}
    block = root.find("ParameterDeclarations")
    if block is not None:
        for d in block.findall("ParameterDeclaration"):
            values[d.get("name", "")] = d.get("value", "")

    def attr(el: ET.Element, name: str, default: str | None = None) -> str:
        raw = el.get(name, default)
        if raw is None:
            raise BadInput(f"attribute {name!r} is required", file=str(path), field=el.tag)
        try:
            return resolve(raw, values)
        except ParameterError as exc:
            raise BadInput(str(exc), file=str(path), field=el.tag) from None

    def num(el: ET.Element, name: str, default: str | None = None) -> float:
        text = attr(el, name, default)
        try:
            value = float(text)
        except ValueError:
            raise BadInput(f"{name}={text!r} is not a number", file=str(path), field=el.tag) from None
        if not math.isfinite(value):
            raise BadInput(f"{name}={text!r} is not finite", file=str(path), field=el.tag)
        return value

    scenario_el = pvd.find("ScenarioFile")
    if scenario_el is None:
        raise BadInput(
            "<ScenarioFile filepath=…> is required", file=str(path), field="ParameterValueDistribution"
        )
    scenario_file = (path.parent / attr(scenario_el, "filepath")).resolve()
    deterministic = pvd.find("Deterministic")
    stochastic = pvd.find("Stochastic")
    if deterministic is not None:
        groups: list[_Group] = []
        for item in deterministic:
            if item.tag == "DeterministicMultiParameterDistribution":
                sets = item.findall("ValueSetDistribution/ParameterValueSet")
                options = tuple(
                    tuple(
                        (attr(a, "parameterRef").lstrip("$"), attr(a, "value"))
                        for a in s.findall("ParameterAssignment")
                    )
                    for s in sets
                )
                if not options:
                    raise BadInput(
                        "a ValueSetDistribution needs a ParameterValueSet", file=str(path), field=item.tag
                    )
                groups.append(_Group(options))
            elif item.tag == "DeterministicSingleParameterDistribution":
                name = attr(item, "parameterName").lstrip("$")
                body = next(iter(item), None)
                if body is None:
                    raise BadInput("empty distribution", file=str(path), field=item.tag)
                if body.tag == "DistributionSet":
                    opts = tuple(((name, attr(e, "value")),) for e in body.findall("Element"))
                elif body.tag == "DistributionRange":
                    step = num(body, "stepWidth")
                    rng_el = body.find("Range")
                    if rng_el is None or step <= 0:
                        raise BadInput(
                            "DistributionRange needs a Range and a positive stepWidth",
                            file=str(path),
                            field=body.tag,
                        )
                    low, high = num(rng_el, "lowerLimit"), num(rng_el, "upperLimit")
                    count = math.floor((high - low) / step + 1e-9) + 1
                    if count > MAX_PERMUTATIONS:
                        raise BadInput(
                            f"DistributionRange of {name!r} has {count} values",
                            file=str(path),
                            field=body.tag,
                        )
                    opts = tuple(((name, _fmt(low + i * step)),) for i in range(max(count, 0)))
                else:
                    raise BadInput(f"<{body.tag}> is not supported", file=str(path), field=item.tag)
                if not opts:
                    raise BadInput(
                        f"the distribution of {name!r} has no values", file=str(path), field=body.tag
                    )
                groups.append(_Group(opts))
        dist = ParameterDistribution(path, scenario_file, groups=tuple(groups))
        if len(dist) > MAX_PERMUTATIONS:
            raise BadInput(
                f"{len(dist)} permutations; at most {MAX_PERMUTATIONS} are allowed", file=str(path)
            )
        return dist
    if stochastic is not None:
        runs = int(num(stochastic, "numberOfTestRuns"))
        file_seed = stochastic.get("randomSeed")
        items: list[_Stochastic] = []
        for d in stochastic.findall("StochasticDistribution"):
            name = attr(d, "parameterName").lstrip("$")
            body = next(iter(d), None)
            if body is None:
                raise BadInput("empty StochasticDistribution", file=str(path), field=d.tag)
            rng_el = body.find("Range")
            lower: float | None = num(rng_el, "lowerLimit") if rng_el is not None else None
            upper: float | None = num(rng_el, "upperLimit") if rng_el is not None else None
            if body.tag == "UniformDistribution":
                if lower is None or upper is None:
                    raise BadInput("UniformDistribution needs a Range", file=str(path), field=body.tag)
                items.append(_Stochastic(name, "uniform", (), lower, upper))
            elif body.tag == "NormalDistribution":
                items.append(
                    _Stochastic(
                        name, "normal", (num(body, "expectedValue"), num(body, "variance")), lower, upper
                    )
                )
            elif body.tag == "LogNormalDistribution":
                items.append(
                    _Stochastic(
                        name, "lognormal", (num(body, "expectedValue"), num(body, "variance")), lower, upper
                    )
                )
            elif body.tag == "PoissonDistribution":
                items.append(_Stochastic(name, "poisson", (num(body, "expectedValue"),), lower, upper))
            elif body.tag == "Histogram":
                bins = []
                for b in body.findall("Bin"):
                    r = b.find("Range")
                    if r is None:
                        raise BadInput("a histogram Bin needs a Range", file=str(path), field="Bin")
                    bins.append((num(b, "weight"), (num(r, "lowerLimit"), num(r, "upperLimit"))))
                if not bins:
                    raise BadInput("a Histogram needs at least one Bin", file=str(path), field=body.tag)
                items.append(_Stochastic(name, "weighted", (), None, None, tuple(bins)))
            elif body.tag == "ProbabilityDistributionSet":
                elements = tuple((num(e, "weight"), attr(e, "value")) for e in body.findall("Element"))
                items.append(_Stochastic(name, "weighted", (), None, None, elements))
            else:
                raise BadInput(f"<{body.tag}> is not supported", file=str(path), field=d.tag)
        return ParameterDistribution(
            path,
            scenario_file,
            stochastic=tuple(items),
            runs=runs,
            seed=int(float(file_seed)) if file_seed else seed,
        )
    raise BadInput("a ParameterValueDistribution needs <Deterministic> or <Stochastic>", file=str(path))
