"""Diagnosis: where simulation and recordings differ, which physics is missing, fitted and shown.

One module per stage, each with its contract in its docstring:
  data        recordings in a canonical order, channels, spreads, noise, the train/validation blocks
  noise       noise levels measured on the data (white, a quantised grid's, correlated by a sensor's filter)
  glitch      a logger's glitches (one or two samples far off their neighbours' line) and held values
  scores      NRMSE, correlation and ratios to the noise of a model's simulations, per channel and on the whole
  motion      what moves in the recordings; the sizes catalogue parameters are measured in
  runner      re-simulation jobs in worker processes
  fitting     Levenberg-Marquardt on bounded slots, 95 % intervals
  pattern     the pattern search that carries a fit on where stick-slip makes its cost rough
  refit       the nominal model re-simulated, the rig's parameters refit; a chosen model refit on all the data
  fidelity    how fine the diagnosis simulates (half as fine as the rig's model where that is as good)
  floors      the noise floors beyond the recordings' noise: a sensor's filter, closed loop, our discretisation
  screening   candidate effects, their signatures, the screening
  sensors     which channels a controller feeds back; a sensor effect's signature on one none reads, unsimulated
  selection   which screened candidates a round fits in full (the shortlist), and which first
  rescreen    the best-screening candidates checked by simulation at their linear estimates
  effect_fit  the fit of one candidate effect (a quantised step's search; from a scan's start too)
  scan        scans of a ripple's period and of a shape parameter (a time constant): where a fit starts
  validate    whether a finding earns its place on validation data; backward elimination; alternatives
  verdict     explained, nothing_missing or unexplained, and why in words
  characteristic a channel's residual that is a static curve of its own value (a nonlinear sensor)
  disturbance a steady line or drift in a residual that no catalogue effect makes (mains hum, a sensor's drift)
  refine      the chosen candidate's polish (a ripple's period scanned again) and the other forms of the same finding
  earlier     an earlier round's choice tried again once the later findings are in
  laws        one friction law in the place of two found at one joint
  period      a ripple's period profiled: the cost with the rest re-solved at each period
  level       a shape or quantised parameter profiled likewise (a time constant, a Stribeck velocity, a delay)
  tolerance   rig parameters at and beyond their tolerance; effects that share a rig parameter's knob
  uncertainty 95 % intervals of the final model's parameters (noise, data split, discretisation, rough cost, a
              ripple's period profile)
  reach       how far an estimate can move before the data tell: a slice, the line to the datasheet's split, a
              difference from the gentler side of a cliff
  settle      backward elimination, the final refit on all the data and the intervals, until they agree
  locate      where the residual stands out of the noise, in which regime
  explain     findings in the rig's physical terms
  experiment  the experiment that would separate explanations the data cannot
  pipeline    the stages in order and the report
"""
from .data import Data, Model, prepare, residual_vector
from .effect_fit import step_search
from .fitting import Slot, intervals, levenberg, refit_parameters
from .locate import locate
from .motion import motion_channel, scale_of
from .pipeline import diagnose
from .runner import simulate_all
from .scores import fit_scores, noise_nrmse, noise_ratio
from .screening import MIN_GAIN, Candidate, concealed, screen
from .selection import shortlist
from .validate import MIN_HELD_GAIN, NOISE_MARGIN

__all__ = [
    "Candidate", "Data", "MIN_GAIN", "MIN_HELD_GAIN", "Model", "NOISE_MARGIN", "Slot", "concealed", "diagnose",
    "fit_scores", "intervals", "levenberg", "locate", "motion_channel", "noise_nrmse", "noise_ratio", "prepare",
    "refit_parameters", "residual_vector", "scale_of", "screen", "shortlist", "simulate_all", "step_search",
]
