"""The unit-generator base class.

A UGen owns an output buffer of ``max_block`` float64 samples and its state arrays. The
graph calls ``process(start, n)`` with the absolute frame ``start`` of the sub-block and
its length ``n``; the ugen reads its inputs' buffers ``[:n]`` and writes ``self.out[:n]``.
Because every ugen carries its state across calls, and events are applied between
sub-blocks at their exact sample, the output does not depend on how frames are grouped.

Subclasses declare ``type_name``, ``inputs``, ``param_specs`` and ``actions``, implement
``_prepare`` (allocate state, design coefficients), ``process`` and ``_reset``, and return
their state arrays from ``state_arrays``.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from jassy.errors import PatchError, suggest
from jassy.params import ParamSpec, Smoothed

SMOOTH_SPEC = ParamSpec(
    "float",
    0.005,
    low=0.0,
    high=10.0,
    unit="s",
    fixed=True,
    doc="duration of the linear ramp applied to smoothed parameter changes",
)


class UGen:
    """Base class of all unit generators."""

    type_name: ClassVar[str] = ""
    #: Names of audio-rate inputs, in positional order.
    inputs: ClassVar[tuple[str, ...]] = ()
    #: Inputs that may stay unconnected (read as silence).
    optional_inputs: ClassVar[tuple[str, ...]] = ()
    #: True for ugens that take any number of inputs (``in0``, ``in1``, ...).
    variadic: ClassVar[bool] = False
    param_specs: ClassVar[dict[str, ParamSpec]] = {}
    #: Event actions other than ``set``: name -> argument specs.
    actions: ClassVar[dict[str, dict[str, ParamSpec]]] = {}
    #: True if the output depends on the input only after a delay (may close a cycle).
    is_delay: ClassVar[bool] = False
    #: True if impact locations downstream of a force source apply to this ugen.
    accepts_location: ClassVar[bool] = False
    #: True if the ugen applies events at their own frame inside a sub-block: parameter
    #: changes through :meth:`set_param_at`, actions through :meth:`act` with their sample
    #: time. The scheduler then hands them over ahead instead of splitting the sub-block.
    inline_events: ClassVar[bool] = False
    #: True for ugens that share a mode budget (anytime synthesis): they implement
    #: :meth:`anytime_attach` and honour ``self.budgeted``.
    supports_budget: ClassVar[bool] = False
    #: True for force sources whose output is the score's impacts alone (ImpactForce): a
    #: mode budget ranks what they strike from the score, not from the force it hears.
    score_impacts_only: ClassVar[bool] = False
    #: True for :class:`Tap`, which carries another ugen's extra output and is named after it.
    is_tap: ClassVar[bool] = False
    #: Names of additional outputs (e.g. the contact force of a closed-loop interaction),
    #: written to ``self.extra[name][:n]`` and read by others through :meth:`tap`.
    outputs: ClassVar[tuple[str, ...]] = ()

    def __init__(self, *sources: UGen, name: str | None = None, where: str | None = None, **params: Any):
        """Create with inputs ``sources`` and parameters; ``where`` prefixes error keys."""
        self.name = name
        where = where or self.type_name
        self.sources: dict[str, UGen] = {}
        self.values: dict[str, Any] = {}
        self.sample_rate: float | None = None
        self.max_block = 0
        self.out = np.zeros(0)
        specs = self.all_specs()
        for key in params:
            if key not in specs:
                hint = suggest(key, specs)
                raise PatchError(
                    f"{where}: unknown parameter {key!r}; expected one of {', '.join(specs)}{hint}"
                )
        for key, spec in specs.items():
            if key in params:
                self.values[key] = self.check_param(key, params[key], f"{where}.{key}")
            elif spec.required:
                raise PatchError(f"{where}.{key}: missing ({self.type_name} needs {spec.expected()})")
            else:
                self.values[key] = spec.default
        self.initial = dict(self.values)
        self.extra: dict[str, np.ndarray] = {}
        self._taps: dict[str, UGen] = {}
        self._event_ramp: float | None = None
        self(*sources)

    # ----------------------------------------------------------------- composition
    @classmethod
    def all_specs(cls) -> dict[str, ParamSpec]:
        return {**cls.param_specs, "smooth": SMOOTH_SPEC}

    def check_param(self, key: str, value: Any, where: str) -> Any:
        """Validate the value of parameter ``key``; PatchError naming ``where``."""
        return self.check_value(self.all_specs()[key], value, where)

    def check_value(self, spec: ParamSpec, value: Any, where: str) -> Any:
        """Validate a value against ``spec``; subclasses extend for model/location kinds."""
        if spec.kind == "location":
            from jassy.modal_model import parse_location

            return parse_location(value, where)
        return spec.coerce(value, where)

    def input_names(self, count: int | None = None) -> tuple[str, ...]:
        if self.variadic:
            n = len(self.sources) if count is None else count
            return tuple(f"in{i}" for i in range(n))
        return self.inputs

    def __call__(self, *sources: UGen, **named: UGen) -> UGen:
        """Connect sources to inputs, positionally or by name; returns self."""
        if self.variadic:
            start = len(self.sources)
            for i, src in enumerate(sources):
                self.connect(src, f"in{start + i}")
        else:
            if len(sources) > len(self.inputs):
                raise PatchError(f"{self.type_name}: takes {len(self.inputs)} input(s), got {len(sources)}")
            for src, inp in zip(sources, self.inputs[: len(sources)], strict=True):
                self.connect(src, inp)
        for inp, src in named.items():
            self.connect(src, inp)
        return self

    def connect(self, source: UGen, input_name: str = "input") -> None:
        if not isinstance(source, UGen):
            raise PatchError(f"{self.type_name}.{input_name}: expected a ugen, got {source!r}")
        if not self.variadic and input_name not in self.inputs:
            raise PatchError(
                f"{self.type_name}: no input {input_name!r}; inputs are {', '.join(self.inputs) or 'none'}"
                f"{suggest(input_name, self.inputs)}"
            )
        self.sources[input_name] = source

    def _combine(self, other: Any, type_name: str, reverse: bool = False) -> UGen:
        from jassy.registry import ugen_class

        if isinstance(other, UGen):
            parts = (other, self) if reverse else (self, other)
            return ugen_class(type_name)(*parts)
        if isinstance(other, (int, float)) and type_name == "Multiply":
            return ugen_class("Gain")(self, gain=float(other))
        return NotImplemented

    def __add__(self, other: Any) -> UGen:
        return self._combine(other, "Mixer")

    def __radd__(self, other: Any) -> UGen:
        return self._combine(other, "Mixer", reverse=True)

    def __mul__(self, other: Any) -> UGen:
        return self._combine(other, "Multiply")

    def __rmul__(self, other: Any) -> UGen:
        return self._combine(other, "Multiply", reverse=True)

    def tap(self, output: str) -> UGen:
        """A node carrying the additional output ``output`` (see :attr:`outputs`)."""
        if output not in self.outputs:
            have = ", ".join(self.outputs) or "none besides its main output"
            raise PatchError(f"{self.type_name} {self.name or ''}: no output {output!r}; it has {have}")
        if output not in self._taps:
            self._taps[output] = Tap(self, output)
        return self._taps[output]

    def __repr__(self) -> str:
        return f"{self.type_name}(name={self.name!r})"

    # ------------------------------------------------------------------ lifecycle
    def prepare(self, sample_rate: float, max_block: int, out: np.ndarray | None = None) -> None:
        """Allocate buffers and state for a render at ``sample_rate`` (Hz).

        ``out``: a float64 buffer of ``max_block`` samples to write into (the graph passes
        a row of its output bus for output nodes); ugens must not keep views of it.
        """
        self.sample_rate = float(sample_rate)
        self.max_block = int(max_block)
        self.values = dict(self.initial)
        self.out = np.zeros(self.max_block) if out is None else out
        self.extra = {name: np.zeros(self.max_block) for name in self.outputs}
        self._silence = np.zeros(self.max_block)
        self._prepare()
        self.reset()

    def input_buffer(self, input_name: str) -> np.ndarray:
        """The buffer feeding ``input_name`` (silence if unconnected)."""
        src = self.sources.get(input_name)
        return self._silence if src is None else src.out

    def ramp_samples(self) -> int:
        """Samples of the ramp for the parameter change being applied."""
        seconds = self._event_ramp if self._event_ramp is not None else self.values["smooth"]
        return int(round(seconds * (self.sample_rate or 0.0)))

    def smoothed(self, key: str) -> Smoothed:
        """A Smoothed holder initialised to the parameter's current value."""
        return Smoothed(float(self.values[key]))

    def _prepare(self) -> None:
        """Allocate state and design coefficients (sample_rate is set)."""

    def _reset(self) -> None:
        """Zero the signal state."""

    def reset(self) -> None:
        """Return to silence, with parameters at their current targets."""
        if self.sample_rate is not None:
            self._reset()

    def process(self, start: int, n: int) -> None:
        """Compute ``self.out[:n]`` for frames ``start .. start + n - 1``."""
        raise NotImplementedError

    # ------------------------------------------------------ hooks of special kinds
    def commit(self, start: int, n: int) -> None:
        """Delays (``is_delay``): store the sub-block's input after every node has run (the
        graph calls it last, which is what lets a feedback loop pass through a delay)."""

    def min_delay_samples(self) -> int:
        """Delays (``is_delay``): the shortest delay in samples the ugen can apply; sub-blocks
        are capped to it when the delay closes a loop."""
        raise NotImplementedError(f"{self.type_name} is not a delay")

    def anytime_attach(self, tables, slot: int, horizon: float, weighting: str) -> None:
        """Budgeted banks (``supports_budget``): start a budgeted render, the bank's rows in
        column ``slot`` of the budget's shared ``tables`` (ugens.modal_budget.BudgetTables),
        where one compiled decision ranks every bank's modes."""
        raise NotImplementedError(f"{self.type_name} takes no mode budget")

    # ---------------------------------------------------------- params and events
    def configure(self, key: str, value: Any) -> None:
        """Set a parameter's initial value (the value every render starts from)."""
        if key not in self.all_specs():
            raise PatchError(
                f"{self.type_name} {self.name!r}: unknown parameter {key!r}{suggest(key, self.all_specs())}"
            )
        value = self.check_param(key, value, f"{self.name}.{key}")
        self.initial[key] = value
        self.values[key] = value

    def set_param(self, key: str, value: Any, jump: bool = False, ramp: float | None = None) -> None:
        """Change a parameter during a render; smoothed parameters ramp (over ``ramp``
        seconds if given, else the ``smooth`` time) unless ``jump``."""
        spec = self.all_specs().get(key)
        if spec is None:
            raise PatchError(
                f"{self.type_name} {self.name!r}: unknown parameter {key!r}{suggest(key, self.all_specs())}"
            )
        if spec.fixed and self.sample_rate is not None:
            raise PatchError(
                f"{self.type_name} {self.name!r}: parameter {key!r} cannot change during a render"
            )
        value = self.check_param(key, value, f"{self.name}.{key}")
        self.values[key] = value
        if self.sample_rate is not None:
            self._event_ramp = ramp
            try:
                self._param_changed(key, value, jump)
            finally:
                self._event_ramp = None

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        """React to a validated parameter change during a render."""

    def set_param_at(self, frame: int, key: str, value: Any, jump: bool, ramp: float | None) -> None:
        """As :meth:`set_param`, taking effect at absolute ``frame`` (at or after the first
        frame of the next :meth:`process`). Only ugens with ``inline_events`` implement it."""
        raise PatchError(f"{self.type_name} {self.name!r}: parameters change only between sub-blocks")

    def act(self, action: str, args: dict[str, Any], sample_time: float) -> None:
        """Perform an event action (validated args) at fractional ``sample_time``."""
        raise PatchError(f"{self.type_name}: no action {action!r}")

    # ----------------------------------------------------------------------- state
    def state_arrays(self) -> dict[str, np.ndarray]:
        """The arrays this ugen owns as state (by reference)."""
        return {}

    def get_state(self) -> dict[str, np.ndarray]:
        """A copy of the state, for saving and later :meth:`set_state`."""
        return {k: v.copy() for k, v in self.state_arrays().items()}

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        arrays = self.state_arrays()
        if set(state) != set(arrays):
            raise PatchError(f"{self.type_name}: state keys {sorted(state)} != {sorted(arrays)}")
        for key, value in state.items():
            arrays[key][...] = value
        self._state_restored()

    def _state_restored(self) -> None:
        """Refresh Python-side caches of the state after :meth:`set_state`."""
        for value in vars(self).values():
            if isinstance(value, Smoothed):
                value.sync()


class Tap(UGen):
    """Carries one additional output of another ugen as a main output (``node.output``)."""

    type_name = "Tap"
    inputs = ("source",)
    is_tap = True

    def __init__(self, source: UGen, output: str):
        super().__init__(source, name=f"{source.name}.{output}" if source.name else None)
        self.output = output

    def process(self, start: int, n: int) -> None:
        self.out[:n] = self.sources["source"].extra[self.output][:n]
