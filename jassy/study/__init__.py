"""Perceptual-latency user studies: audio-haptic asynchrony experiments end to end.

``jassy study run DESIGN.toml`` renders every trial's stimulus exactly (offset applied in
samples on the one clock), presents it (``--present live`` on the device, ``none`` for
simulated observers), measures the presented offset from the buffers, collects responses
(terminal keys, a window, a simulated observer or any callable) and appends each trial to
a CSV file (JSON header in a sidecar) so a session can be interrupted and resumed.
``jassy study analyze RESULTS.csv ...`` fits the task's psychometric model per condition
(per participant, pooled and group; profile-likelihood intervals, "not identifiable"
where the design cannot say), plots and exports. Methods: constant stimuli, staircases,
QUEST, QUEST+; tasks: TOJ, SJ, 2AFC, 3AFC.
"""

import importlib

#: Public names -> the module defining them, imported on first use (the CLI stays light).
#: Public names -> the module defining them, imported on first use (the CLI stays light).
_EXPORTS = {
    "CallableResponder": "jassy.study.observer",
    "ConstantTrack": "jassy.study.methods",
    "Design": "jassy.study.design",
    "DesignError": "jassy.study.design",
    "KeyboardResponder": "jassy.study.observer",
    "LivePresenter": "jassy.study.runner",
    "ObserverSpec": "jassy.study.design",
    "OfflinePresenter": "jassy.study.runner",
    "QuestPlusTrack": "jassy.study.methods",
    "QuestTrack": "jassy.study.methods",
    "Response": "jassy.study.observer",
    "Session": "jassy.study.runner",
    "SessionResult": "jassy.study.runner",
    "SimulatedObserver": "jassy.study.observer",
    "Staircase": "jassy.study.methods",
    "TrialInfo": "jassy.study.observer",
    "analyze": "jassy.study.analysis",
    "balanced_latin_square": "jassy.study.design",
    "export_fits": "jassy.study.analysis",
    "fit": "jassy.study.fitting",
    "format_report": "jassy.study.analysis",
    "load_design": "jassy.study.design",
    "make_model": "jassy.study.models",
    "measure_offset": "jassy.study.runner",
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
    "ConstantTrack",
    "Design",
    "DesignError",
    "KeyboardResponder",
    "LivePresenter",
    "ObserverSpec",
    "OfflinePresenter",
    "QuestPlusTrack",
    "QuestTrack",
    "Response",
    "Session",
    "SessionResult",
    "SimulatedObserver",
    "Staircase",
    "TrialInfo",
    "analyze",
    "balanced_latin_square",
    "export_fits",
    "fit",
    "format_report",
    "load_design",
    "make_model",
    "measure_offset",
    "parse_design",
    "plot_report",
    "read_rows",
    "render_trial",
    "run_study",
]
