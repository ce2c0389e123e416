"""The adapter around optuna: samplers per strategy, the persisted study, asking and telling in batches.

The study is an optuna journal: its log (every trial with its sampler state, e.g. CMA-ES's) is a list of
JSON objects the driver stores with the results; this process is its only writer, so it lives in memory
between stores (no file locks per ask). Each round loads it with a sampler seeded from (seed, round), so the points a round asks depend only on the seed, the
round and the results before it: a search interrupted mid-round asks the same points again when it resumes.
optuna is imported here only.
"""

from __future__ import annotations

import hashlib
import warnings
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from simcore.errors import BadInput
from simcore.search.space import Dimension
from simcore.spec import ParameterValue

if TYPE_CHECKING:
    import optuna

STUDY_NAME = "carlos-search"


def round_seed(seed: int, round_number: int) -> int:
    digest = hashlib.sha256(f"{seed}:{round_number}".encode()).digest()
    return int.from_bytes(digest[:4], "big") & 0x7FFFFFFF


def check_strategy(strategy: str) -> None:
    """Bad input when the strategy's optional dependency is missing (gp needs PyTorch)."""
    if strategy == "gp":
        try:
            import torch  # noqa: F401
        except ImportError:
            raise BadInput(
                "strategy gp needs PyTorch (optuna's GPSampler): pip install torch, or choose tpe or cmaes",
                field="spec.search.strategy",
            ) from None


def make_sampler(strategy: str, seed: int, startup: int) -> optuna.samplers.BaseSampler:
    """The sampler of a strategy. The adaptive ones start with `startup` uniform random points."""
    import optuna

    warnings.filterwarnings("ignore", category=optuna.exceptions.ExperimentalWarning)
    random = optuna.samplers.RandomSampler(seed=seed)
    if strategy == "random":
        return random
    if strategy == "lhs":
        return optuna.samplers.QMCSampler(
            qmc_type="sobol",
            scramble=True,
            seed=seed,
            independent_sampler=random,
            warn_independent_sampling=False,
        )
    if strategy in ("tpe", "boundary"):
        return optuna.samplers.TPESampler(
            seed=seed, n_startup_trials=startup, multivariate=True, constant_liar=True
        )
    if strategy == "cmaes":
        return optuna.samplers.CmaEsSampler(
            seed=seed, n_startup_trials=startup, independent_sampler=random, warn_independent_sampling=False
        )
    if strategy == "gp":
        return optuna.samplers.GPSampler(
            seed=seed, n_startup_trials=startup, independent_sampler=random, warn_independent_sampling=False
        )
    raise ValueError(f"unknown strategy {strategy!r}")


def _distribution(dimension: Dimension) -> Any:
    import optuna

    if dimension.choices is not None:
        return optuna.distributions.CategoricalDistribution(dimension.choices)
    if dimension.integer:
        import math

        return optuna.distributions.IntDistribution(math.ceil(dimension.low), math.floor(dimension.high))
    return optuna.distributions.FloatDistribution(dimension.low, dimension.high)


def _memory_backend(log: list[dict[str, Any]]) -> Any:
    from optuna.storages.journal import BaseJournalBackend

    class MemoryJournal(BaseJournalBackend):
        """optuna's journal over a list (appended to in place)."""

        def read_logs(self, log_number_from: int) -> list[dict[str, Any]]:
            return log[log_number_from:]

        def append_logs(self, logs: list[dict[str, Any]]) -> None:
            log.extend(logs)

    return MemoryJournal()


class Study:
    """The optuna study of a search over its journal `log` (JSON objects, appended to in place)."""

    def __init__(
        self, log: list[dict[str, Any]], strategy: str, seed: int, round_number: int, startup: int
    ) -> None:
        import optuna
        from optuna.storages.journal import JournalStorage

        optuna.logging.set_verbosity(optuna.logging.WARNING)
        storage = JournalStorage(_memory_backend(log))
        self._optuna = optuna
        self.study = optuna.create_study(
            study_name=STUDY_NAME,
            storage=storage,
            sampler=make_sampler(strategy, round_seed(seed, round_number), startup),
            direction="minimize",
            load_if_exists=True,
        )
        self._asked: dict[int, Any] = {}

    def ask(self, space: Sequence[Dimension], count: int) -> list[dict[str, ParameterValue]]:
        """`count` new points, in order."""
        distributions = {d.name: _distribution(d) for d in space}
        points = []
        for _ in range(count):
            trial = self.study.ask(distributions)
            self._asked[len(self._asked)] = trial
            points.append(dict(trial.params))
        return points

    def tell(self, position: int, value: float | None) -> None:
        """The loss of the `position`-th point asked (None: the run failed to produce one)."""
        trial = self._asked[position]
        if value is None:
            self.study.tell(trial, state=self._optuna.trial.TrialState.FAIL)
        else:
            self.study.tell(trial, value)

    def completed(self) -> int:
        states = (self._optuna.trial.TrialState.COMPLETE, self._optuna.trial.TrialState.FAIL)
        return len(self.study.get_trials(deepcopy=False, states=states))
