"""Perceptual-latency user studies: audio-haptic asynchrony experiments end to end.

``jassy study run DESIGN.toml`` renders every trial's stimulus exactly (offset applied in
samples on the one clock), presents it (``--present live`` on the device, ``none`` for
simulated observers), measures the presented offset from the buffers, collects responses
(terminal keys, a window, a simulated observer or any callable) and appends each trial to
a CSV file (JSON header in a sidecar) so a session can be interrupted and resumed.
``jassy study analyze RESULTS.csv ...`` fits psychometric functions (PSS, JND, bootstrap
CIs), pools participants and plots.
"""

from jassy.study.analysis import Fit, analyze, fit_psychometric, format_report, plot_report
from jassy.study.design import Design, DesignError, ObserverSpec, load_design, parse_design
from jassy.study.observer import (
    CallableResponder,
    KeyboardResponder,
    Response,
    SimulatedObserver,
    TrialInfo,
    p_positive,
)
from jassy.study.runner import (
    LivePresenter,
    OfflinePresenter,
    Session,
    SessionResult,
    measure_offset,
    read_rows,
    render_trial,
    run_study,
)

__all__ = [
    "CallableResponder",
    "Design",
    "DesignError",
    "Fit",
    "KeyboardResponder",
    "LivePresenter",
    "ObserverSpec",
    "OfflinePresenter",
    "Response",
    "Session",
    "SessionResult",
    "SimulatedObserver",
    "TrialInfo",
    "analyze",
    "fit_psychometric",
    "format_report",
    "load_design",
    "measure_offset",
    "p_positive",
    "parse_design",
    "plot_report",
    "read_rows",
    "render_trial",
    "run_study",
]
