"""A run seen as pyABC's ``History``: enough of its reading interface (read-only) that pyABC's
plotting functions draw a bitrock run as they draw a pyABC one."""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from ._errors import InputError


class History:
    """A read-only view of a :class:`bitrock.Result` with the methods of ``pyabc.History``
    that pyABC's plots read: ``max_t``, ``get_distribution``, ``get_model_probabilities``,
    ``get_all_populations``, ``get_weighted_distances``, ``get_nr_particles_per_population``
    and ``alive_models``. Models are numbered as pyABC numbers them, 0, 1, … in the order of
    the run's laws (``model_names`` maps them back); the distance is bitrock's misfit ρ. As in
    pyABC, ``get_all_populations`` starts with a calibration row (``t = -1``, ε = ∞) that
    ``plot_epsilons`` skips. Made by :meth:`bitrock.Result.history`."""

    def __init__(self, result: Any) -> None:
        self._result = result
        self.id = 1

    @property
    def model_names(self) -> list[str]:
        """The law of each model index."""
        return list(self._result.laws)

    @property
    def max_t(self) -> int:
        """The last population's index."""
        return len(self._result.document["populations"]) - 1

    @property
    def n_populations(self) -> int:
        return self.max_t + 1

    def _law(self, m: int | str) -> str:
        if isinstance(m, str):
            if m not in self.model_names:
                raise InputError(f"m: the run's laws are {', '.join(self.model_names)}, got {m!r}", "m")
            return m
        names = self.model_names
        if not 0 <= int(m) < len(names):
            raise InputError(f"m: the run's models are 0..{len(names) - 1} ({', '.join(names)}), got {m}", "m")
        return names[int(m)]

    def _t(self, t: int | None) -> int:
        return self.max_t if t is None else int(t)

    def get_distribution(self, m: int | str = 0, t: int | None = None) -> tuple[pd.DataFrame, np.ndarray]:
        """Model ``m``'s particles in population ``t`` (the last by default) and their weights
        normalised within the model."""
        return self._result.get_distribution(self._law(m), self._t(t))

    def get_model_probabilities(self, t: int | None = None) -> pd.DataFrame:
        """For one population ``t``: a frame indexed by model ``m`` with a column ``p`` (models
        with particles only, as pyABC stores them); without ``t``: population × model."""
        table = self._result.model_probabilities[self.model_names]
        table = table.rename(columns={law: m for m, law in enumerate(self.model_names)})
        table.index.name = "t"
        table.columns.name = "m"
        if t is None:
            return table
        row = table.loc[int(t)]
        frame = pd.DataFrame({"p": row[row > 0]})
        frame.index.name = "m"
        return frame

    def alive_models(self, t: int | None = None) -> list[int]:
        """The models with particles in population ``t``."""
        return list(self.get_model_probabilities(self._t(t)).index)

    def nr_of_models_alive(self, t: int | None = None) -> int:
        return len(self.alive_models(t))

    def get_nr_particles_per_population(self) -> pd.Series:
        """Particles per population, indexed by ``t`` (from -1, the calibration, which has none)."""
        counts = pd.Series(
            [0] + [p["accepted"] for p in self._result.document["populations"]],
            index=pd.Index(range(-1, self.max_t + 1), name="t"),
            name="t",
        )
        return counts

    def get_all_populations(self) -> pd.DataFrame:
        """One row per population (``t``, ``population_end_time``, ``wall_time`` in seconds,
        ``samples`` drawn, ``epsilon``, ``particles``), after a calibration row ``t = -1``."""
        rows = [{"t": -1, "population_end_time": pd.NaT, "wall_time": 0.0, "samples": 0, "epsilon": np.inf, "particles": 0}]
        for p in self._result.document["populations"]:
            rows.append(
                {
                    "t": p["index"],
                    "population_end_time": pd.NaT,
                    "wall_time": p["seconds"],
                    "samples": p["draws"],
                    "epsilon": np.inf if p["epsilon"] is None else p["epsilon"],
                    "particles": p["accepted"],
                }
            )
        return pd.DataFrame(rows)

    def get_weighted_distances(self, t: int | None = None) -> pd.DataFrame:
        """Every particle of population ``t``: its distance (ρ) and its weight across all
        models (summing to 1 over the population, as pyABC's)."""
        particles = self._result.particles(self._t(t))
        rho = np.concatenate([particles[law][3] for law in particles]) if particles else np.zeros(0)
        w = np.concatenate([particles[law][2] for law in particles]) if particles else np.zeros(0)
        return pd.DataFrame({"distance": rho, "w": w})

    def __repr__(self) -> str:
        return f"<bitrock.History of a run: {self.n_populations} populations, models {dict(enumerate(self.model_names))}>"
