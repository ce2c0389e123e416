"""Index → run: the pure mapping from a run index to its scenario, parameters and seed.

Index order (DESIGN.md): scenarios in manifest order; within a scenario the matrix permutations in mixed
radix over the matrix keys in manifest order, last key fastest; then repetitions (sweep.repetitions); then,
innermost, repeats (execution.repeat). Nothing is ever
materialised: any index is computed alone, on any machine, in O(number of matrix keys).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from math import prod

from simcore.errors import BadInput
from simcore.spec import ParameterValue, ScenarioRef, SimulationRunSpec


@dataclass(frozen=True, slots=True)
class RunPoint:
    """One run of a SimulationRun."""

    index: int
    scenario: ScenarioRef
    permutation: int  # index of the matrix permutation within the scenario
    repetition: int
    sweep_values: dict[str, ParameterValue]  # the matrix values of this permutation
    parameters: dict[str, ParameterValue]  # every override for the scenario: spec < scenario < matrix
    seed: int
    repeat: int = 0  # which run of the point (execution.repeat), 0-based


def permutation(matrix: Sequence[tuple[str, Sequence[ParameterValue]]], k: int) -> dict[str, ParameterValue]:
    """The k-th permutation of `matrix` in mixed radix, last key fastest."""
    size = prod(len(values) for _, values in matrix)
    if not 0 <= k < size:
        raise IndexError(f"permutation {k} is out of range 0..{size - 1}")
    digits: dict[str, ParameterValue] = {}
    for name, values in reversed(matrix):
        k, digit = divmod(k, len(values))
        digits[name] = values[digit]
    return {name: digits[name] for name, _ in matrix}


class Plan(Sequence[RunPoint]):
    """The runs of a spec as a lazy sequence: `len(plan)`, `plan[i]`, iteration."""

    def __init__(self, spec: SimulationRunSpec) -> None:
        self.spec = spec
        self.matrix: tuple[tuple[str, tuple[ParameterValue, ...]], ...] = tuple(
            (name, tuple(values)) for name, values in spec.sweep.matrix.items()
        )
        self.distribution = None
        if spec.sweep.distribution_config_map_ref is not None:
            raise BadInput(
                "a distribution from a ConfigMap exists on a cluster only (the operator reads it); locally "
                "give the file's path in 'distribution'",
                field="spec.sweep.distributionConfigMapRef",
            )
        if spec.sweep.distribution:
            from simcore.scenario.distribution import load_distribution

            self.distribution = load_distribution(spec.sweep.distribution, seed=spec.simulation.seed)
        self.matrix_permutations = prod(len(values) for _, values in self.matrix)
        self.permutations = self.matrix_permutations * (len(self.distribution) if self.distribution else 1)
        self.repetitions = spec.sweep.repetitions
        self.repeat = spec.execution.repeat
        self.vary_seeds = spec.execution.seed_policy == "vary"
        self.per_scenario = self.permutations * self.repetitions * self.repeat
        self.selected = spec.sweep.indexes
        whole = len(self.spec.scenarios) * self.per_scenario
        for index in self.selected or ():
            if index >= whole:
                raise BadInput(
                    f"index {index} is out of range: the sweep has {whole} indexes",
                    field="spec.sweep.indexes",
                )

    def __len__(self) -> int:
        if self.selected is not None:
            return len(self.selected)
        return len(self.spec.scenarios) * self.per_scenario

    def __getitem__(self, index: int) -> RunPoint:  # type: ignore[override]
        if not isinstance(index, int):
            raise TypeError("plan indexes are integers")
        total = len(self)
        if not 0 <= index < total:
            raise IndexError(f"index {index} is out of range 0..{total - 1}")
        if self.selected is not None:  # index k runs the sweep's index selected[k]
            return replace(self.sweep_point(self.selected[index]), index=index)
        return self.sweep_point(index)

    def sweep_point(self, index: int) -> RunPoint:
        """Index `index` of the whole sweep (`spec.sweep.indexes` aside)."""
        scenario_index, k = divmod(index, self.per_scenario)
        k, repeat = divmod(k, self.repeat)
        perm, repetition = divmod(k, self.repetitions)
        scenario = self.spec.scenarios[scenario_index]
        if self.distribution is not None:
            # the distribution's permutations run fastest, after the matrix keys
            matrix_perm, dist_perm = divmod(perm, len(self.distribution))
            values = {**permutation(self.matrix, matrix_perm), **self.distribution[dist_perm]}
        else:
            values = permutation(self.matrix, perm)
        parameters: dict[str, ParameterValue] = {**self.spec.parameters, **scenario.parameters, **values}
        return RunPoint(
            index=index,
            scenario=scenario,
            permutation=perm,
            repetition=repetition,
            sweep_values=values,
            parameters=parameters,
            seed=self.spec.simulation.seed
            + repetition
            + (repeat * self.repetitions if self.vary_seeds else 0),
            repeat=repeat,
        )

    def point_of(self, index: int) -> int:
        """The point (scenario, permutation, repetition) of an index of this plan: indexes with the same
        point are repeats of one another (execution.repeat)."""
        if self.selected is not None:
            index = self.selected[index]
        return index // self.repeat

    def __iter__(self) -> Iterator[RunPoint]:
        for index in range(len(self)):
            yield self[index]

    def indexes_of(self, scenario_name: str) -> range:
        """The indexes of a scenario in the whole sweep (without `spec.sweep.indexes`)."""
        for position, scenario in enumerate(self.spec.scenarios):
            if scenario.name == scenario_name:
                return range(position * self.per_scenario, (position + 1) * self.per_scenario)
        raise KeyError(scenario_name)


def describe(values: Mapping[str, ParameterValue]) -> str:
    """`a=1,b=x` — a permutation in one short line (test names, progress)."""
    return ",".join(f"{name}={value}" for name, value in values.items())
