"""Studies: many closed-loop trials run on an executor (see :mod:`.runner`)."""
from quadruped_control.studies.runner import StudyError, run_trials, spec_key, trial_path

__all__ = ["StudyError", "run_trials", "spec_key", "trial_path"]
