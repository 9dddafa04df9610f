"""The named parameter vector ρ held as one frozen array ``rho``, for mechanisms whose
parameters are not stored field by field (the deltas, the rotary and sliding hexapods).

A dataclass mechanism with fields ``name``, ``rho`` and ``covariance`` mixes in
:class:`ParameterVector`, sets :attr:`PARAM_NAMES` and :attr:`PARAM_IS_ANGLE` (and
:attr:`LABEL`, what it is called in messages), calls :meth:`_freeze_params` from
``__post_init__`` and may override :meth:`parameter_problem`."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from pkmcal.errors import PkmcalError


class ParameterVector:
    """``param_names``, ``param_is_angle``, ``params``, ``with_params`` and the checked
    ``_rho(params)`` of a mechanism holding ρ as ``rho`` (module docstring)."""

    PARAM_NAMES: tuple[str, ...] = ()
    PARAM_IS_ANGLE: tuple[bool, ...] = ()
    LABEL = "machine"

    def _freeze_params(self) -> None:
        """``rho`` as a read-only float array of the right length, then the geometry
        checked (``parameter_problem``): call from ``__post_init__``."""
        rho = self._rho(np.array(self.rho, dtype=float).reshape(-1))      # a checked copy
        rho.setflags(write=False)
        object.__setattr__(self, "rho", rho)
        problem = self.parameter_problem()
        if problem is not None:
            raise PkmcalError(f"{self.LABEL} '{self.name}': {problem[0]} {problem[1]}")

    def parameter_problem(self) -> tuple[str, str] | None:
        """``(name, why)`` of the first parameter that makes the machine impossible."""
        return None

    def _rho(self, params) -> np.ndarray:
        """``params`` (default the machine's) as a checked float vector."""
        if params is None:
            return self.rho
        params = np.asarray(params, dtype=float)
        if params.shape != (len(self.PARAM_NAMES),):
            raise PkmcalError(f"{self.LABEL} '{self.name}' has {len(self.PARAM_NAMES)} parameters; got {params.shape}")
        return params

    @property
    def param_names(self) -> tuple[str, ...]:
        return self.PARAM_NAMES

    @property
    def param_is_angle(self) -> tuple[bool, ...]:
        return self.PARAM_IS_ANGLE

    @property
    def params(self) -> np.ndarray:
        return self.rho.copy()

    def with_params(self, params: np.ndarray, name: str | None = None, covariance=None):
        """The same machine with parameters ``params`` (and ``name``, ``covariance``)."""
        return replace(self, rho=np.asarray(params, dtype=float), name=self.name if name is None else name,
                       covariance=covariance)


__all__ = ["ParameterVector"]
