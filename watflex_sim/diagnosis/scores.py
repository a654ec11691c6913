"""How close a model's simulations are to the recordings: NRMSE, correlation and ratios to the noise.

Contract: `fit_scores(data, sims, part)` gives the report's scores on a part ("train", "held_out", "all"): mean NRMSE
and correlation over channels and recordings (recordings.md), the mean ratio of RMS residual to noise (1 = as close
as the noise allows), each channel's ratio judged alone and the channel furthest above its noise; `channel_ratios`
the per-recording rows behind them; `noise_nrmse` what noise alone leaves; `step` a row of the report's "steps".
"""
from __future__ import annotations

import math

import numpy as np

from ..metrics import correlation, nrmse
from ..recording import Recording
from .data import Data, Model, in_part, noise_alone, rms_residual

def channel_ratios(data: Data, sims: list[Recording], part: str = "all") -> list[dict]:
    """Per recording and channel: RMS residual / noise rms on a part (1 = within the noise), and (`alone`) / the
    noise with our discretisation error counted DISCRETISATION_COUNT times: what the channel is judged by on its own."""
    out = []
    for i, (rec, sim, name, chans, noise, train) in enumerate(zip(data.recordings, sims, data.names, data.channels,
                                                                  data.noise, data.train)):
        mask = in_part(train, part)
        for c in chans:
            rms = rms_residual(rec, sim, c, mask, least=10)
            if rms is not None:
                out.append({"recording": name, "channel": c, "ratio": rms / noise[c],
                            "alone": rms / noise_alone(data, i, c)})
    return out


def noise_ratio(data: Data, sims: list[Recording] | None, part: str = "all") -> float:
    """Mean over recordings and channels of RMS residual / noise on a part: what the verdicts judge
    (1 = the model is as close as the noise allows); inf if the model diverged."""
    if sims is None:
        return math.inf
    return _mean_ratio(channel_ratios(data, sims, part))


def _mean_ratio(ratios: list[dict]) -> float:
    return float(np.mean([r["ratio"] for r in ratios])) if ratios else 0.0


def typical_ratios(ratios: list[dict]) -> dict[str, float]:
    """Per channel, the median over recordings of its ratio judged alone (`channel_ratios`' "alone")."""
    per: dict[str, list[float]] = {}
    for r in ratios:
        per.setdefault(r["channel"], []).append(r["alone"])
    return {c: float(np.median(v)) for c, v in per.items()}


def worst_channel(ratios: list[dict]) -> tuple[str, float]:
    """The channel furthest above its noise, and its ratio, from `channel_ratios`: the median over
    recordings of RMS residual / noise, the discretisation part of the noise counted DISCRETISATION_COUNT times
    (`alone`). A mean over channels hides one channel left unexplained (a motor current 1.5x its noise in every
    recording); the median over recordings does not count one recording where a stick-slipping joint stopped
    elsewhere (a clean Watflex case: 2.8x in one step, 0.6-0.9x in two). A channel whose floor is mostly our
    discretisation is judged by its upper estimate, as a window is (locate.local_null): one pair of discretisations
    estimates it, and a channel that chatters differs at every discretisation (seed 78's clean two-joint
    watflex-1875e76b and -b06c2d87, the rig's parameters found to 0.1-0.3 %: the shoulder's torque command, its floor
    its discretisation alone, 1.50 x and 2.11 x, 0.75 x and 1.05 x counted twice; the mean over channels 0.74-0.87 x)."""
    return max(typical_ratios(ratios).items(), key=lambda cv: cv[1], default=("", 0.0))


def fit_scores(data: Data, sims: list[Recording] | None, part: str = "all") -> dict:
    """Mean NRMSE and correlation over channels and recordings (recordings.md), the noise ratio, each
    channel's (`channel_ratios`, typical_ratios) and the channel furthest above its noise (`worst_channel`,
    `worst_ratio`), on a part."""
    if sims is None:
        return {"nrmse": math.inf, "correlation": 0.0, "noise_ratio": math.inf, "worst_channel": "", "worst_ratio": math.inf,
                "channel_ratios": {}}
    errors, corrs = [], []
    for rec, sim, chans, train in zip(data.recordings, sims, data.channels, data.train):
        mask = in_part(train, part)
        if mask.sum() < 10:
            continue
        for c in chans:
            errors.append(nrmse(rec.channels[c][mask], sim.channels[c][mask]))
            corrs.append(correlation(rec.channels[c][mask], sim.channels[c][mask]))
    ratios = channel_ratios(data, sims, part)
    worst, ratio = worst_channel(ratios)
    return {"nrmse": float(np.nanmean(errors)), "correlation": float(np.nanmean(corrs)),
            "noise_ratio": _mean_ratio(ratios), "worst_channel": worst, "worst_ratio": ratio,
            "channel_ratios": typical_ratios(ratios)}


def noise_nrmse(data: Data, part: str = "all") -> float:
    """Mean NRMSE that measurement noise alone leaves on a part, averaged like fit_scores."""
    floors = [v for floor, train in zip(data.noise_floor, data.train) if in_part(train, part).sum() >= 10
              for v in floor.values()]
    return float(np.mean(floors)) if floors else 0.0


def step(label: str, data: Data, sims: list[Recording], model: Model) -> dict:
    """One stage of the report's 'steps': its label, training and validation NRMSE and noise ratio, and the model."""
    train, held = fit_scores(data, sims, "train"), fit_scores(data, sims, "held_out")
    return {"model": label, "train_nrmse": train["nrmse"], "held_out_nrmse": held["nrmse"],
            "train_noise_ratio": train["noise_ratio"], "held_out_noise_ratio": held["noise_ratio"],
            "effects": [dict(e) for e in model.effects], "parameters": dict(model.parameters)}


def noise_table(data: Data) -> list[dict]:
    """The report's noise per recording and channel: measured, declared by the rig, what our discretisation leaves
    (against a 2 x finer model), in the channel's unit."""
    model = data.discretisation or [{} for _ in data.names]
    return [{"recording": n, "channel": c, "noise": noise[c], "declared": float(data.rig.channels[c].get("noise", 0.0)),
             "discretisation": error.get(c, 0.0), "unit": data.rig.channels[c]["unit"]}
            for n, chans, noise, error in zip(data.names, data.channels, data.noise, model) for c in chans]
