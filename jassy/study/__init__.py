"""Perceptual-latency user studies: audio-haptic asynchrony experiments end to end.

``jassy study run DESIGN.toml`` renders every trial's stimulus exactly (offset applied in
samples on the one clock), presents it (``--present live`` on the device, ``none`` for
simulated observers), measures the presented offset from the buffers, collects responses
(terminal keys, a window, a simulated observer or any callable) and appends each trial to
a CSV file (JSON header in a sidecar) so a session can be interrupted and resumed.
``jassy study analyze RESULTS.csv ...`` fits psychometric functions (PSS, JND, bootstrap
CIs), pools participants and plots.
"""

import importlib

#: Public names -> the module defining them, imported on first use (the CLI stays light).
_EXPORTS = {
    "CallableResponder": "jassy.study.observer",
    "Design": "jassy.study.design",
    "DesignError": "jassy.study.design",
    "Fit": "jassy.study.analysis",
    "KeyboardResponder": "jassy.study.observer",
    "LivePresenter": "jassy.study.runner",
    "ObserverSpec": "jassy.study.design",
    "OfflinePresenter": "jassy.study.runner",
    "Response": "jassy.study.observer",
    "Session": "jassy.study.runner",
    "SessionResult": "jassy.study.runner",
    "SimulatedObserver": "jassy.study.observer",
    "TrialInfo": "jassy.study.observer",
    "analyze": "jassy.study.analysis",
    "fit_psychometric": "jassy.study.analysis",
    "format_report": "jassy.study.analysis",
    "load_design": "jassy.study.design",
    "measure_offset": "jassy.study.runner",
    "p_positive": "jassy.study.observer",
    "parse_design": "jassy.study.design",
    "plot_report": "jassy.study.analysis",
    "read_rows": "jassy.study.runner",
    "render_trial": "jassy.study.runner",
    "run_study": "jassy.study.runner",
}


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'jassy.study' has no attribute {name!r}")


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
