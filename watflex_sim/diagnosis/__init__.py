"""Diagnosis: where simulation and recordings differ, which physics is missing, fitted and shown.

One module per stage, each with its contract in its docstring:
  data        recordings in a canonical order, channels, spreads, noise, the train/validation blocks
  runner      re-simulation jobs in worker processes
  fitting     Levenberg-Marquardt on bounded slots, 95 % intervals
  screening   candidate effects, their signatures, screening and candidate fits
  refine      the chosen candidate's polish and the other forms of the same finding
  tolerance   rig parameters at and beyond their tolerance; effects that share a rig parameter's knob
  uncertainty 95 % intervals of the final model's parameters (noise, data split, discretisation, rough cost)
  locate      where the residual stands out of the noise, in which regime
  explain     findings in the rig's physical terms
  experiment  the experiment that would separate explanations the data cannot
  pipeline    the stages in order, the verdict and the report
"""
from .data import (Data, Model, fit_scores, motion_channel, noise_nrmse, noise_ratio, prepare, residual_vector,
                   scale_of)
from .fitting import Slot, intervals, levenberg, refit_parameters
from .locate import locate
from .pipeline import MIN_GAIN, MIN_HELD_GAIN, NOISE_MARGIN, diagnose
from .runner import simulate_all
from .screening import Candidate, screen, shortlist, step_search

__all__ = [
    "Candidate", "Data", "MIN_GAIN", "MIN_HELD_GAIN", "Model", "NOISE_MARGIN", "Slot", "diagnose", "fit_scores",
    "intervals", "levenberg", "locate", "motion_channel", "noise_nrmse", "noise_ratio", "prepare",
    "refit_parameters", "residual_vector", "scale_of", "screen", "shortlist", "simulate_all", "step_search",
]
