"""The verdict: `explained`, `nothing_missing` or `unexplained`, and why in words.

Contract: `verdict_of`: `nothing_missing` only when a model without findings is within NOISE_MARGIN x the noise on
training AND validation data and no window is far above its local null, `explained` when the findings bring both there
(or remove EXPLAINED_SHARE of the excess, unless the whole is within the noise and one channel stays far above it:
`lone_channel`), `unexplained` otherwise, and whenever a channel's residual is a static curve of its own value
(`characteristic.curved_channels`: a nonlinear characteristic the catalogue does not have) or a steady line or drift
(disturbance.disturbances); `verdict_reason` says why in words.
"""
from __future__ import annotations

from .data import DISCRETISATION_COUNT, Model
from .locate import LOCAL_MARGIN, LOCAL_WINDOW_S
from .validate import EXPLAINED_SHARE, LOCAL_GAIN, NOISE_MARGIN, within_noise

LONE_CHANNEL = 2.0 * NOISE_MARGIN  # findings that remove EXPLAINED_SHARE explain the data unless the whole is within
# NOISE_MARGIN and one channel stays this far above its noise: the share is of the mean over channels, which one
# channel hardly moves. Of 87 `explained` reports of seeds 75-81 (and their re-runs) every channel was at most 1.55 x
# its noise but one: seed 81's laser_arm-493fe444, a motor-current sensor gain x1.82 beside a backlash, read as beam
# damping, its motor current left at 2.82 x


def verdict_of(model: Model, train: dict, held: dict, share: float, curved: list[dict], local: list[dict] = (),
               disturbed: list[dict] = ()) -> str:
    """The verdict for a final `model` whose fit_scores are `train` and `held` (validation), its findings
    removing `share` of validation's excess over the noise (explained_share), `curved` its
    characteristic.curved_channels, `local` the windows far above their local null that asked for a round
    (locate.local_excess), `disturbed` the channels whose residual carries a steady line or drift no catalogue effect
    makes (disturbance.disturbances)."""
    if curved or disturbed:
        return "unexplained"
    if not model.effects:
        return "nothing_missing" if within_noise(train, held) and not local else "unexplained"
    if within_noise(train, held):
        return "explained"
    return "explained" if share >= EXPLAINED_SHARE and not lone_channel(train, held) else "unexplained"


def lone_channel(train: dict, held: dict) -> tuple[str, float] | None:
    """(channel, its ratio to its noise) where training and validation are within NOISE_MARGIN x the noise on the
    whole (the mean over channels) but that channel stays more than LONE_CHANNEL x its noise on one of them; None
    otherwise. Such a channel is something the findings do not explain, however much of the mean they removed."""
    if max(train["noise_ratio"], held["noise_ratio"]) > NOISE_MARGIN:
        return None
    worst = max((train, held), key=lambda s: s["worst_ratio"])
    return (worst["worst_channel"], worst["worst_ratio"]) if worst["worst_ratio"] > LONE_CHANNEL else None


def verdict_reason(verdict: str, train: dict, held: dict, refit_train: dict, refit_held: dict, share: float,
                   curved: list[dict], local: list[dict] = (), limit: int | None = None, disturbed: list[dict] = (),
                   kept: int | None = None) -> str:
    """Why the verdict, in words; `limit`: the number of findings at which the search stopped without asking whether
    a further effect would earn its place (max_effects), None where it asked; `kept`: the findings reported, said where
    elimination left fewer than the limit."""
    since = (f"; {kept} kept, the others dropped since" if kept is not None and limit is not None and kept < limit
             else "")
    stopped = (f"the search stopped at its limit of {limit} finding{'s' if limit != 1 else ''} (--max-effects{since}) "
               "before asking whether a further effect earns its place")
    worst = max((train, held), key=lambda s: s["worst_ratio"])
    now = (f"training {train['noise_ratio']:.2f} x, validation {held['noise_ratio']:.2f} x the noise; furthest channel "
           f"{worst['worst_channel']} at {worst['worst_ratio']:.2f} x, our discretisation counted {DISCRETISATION_COUNT:g} x there")
    if curved:
        return ("; ".join(f"{c['channel']}'s residual is a static curve of its own value: beyond a gain and an offset "
                          f"({c['noise_ratio']:.2f} x its noise left), a cubic map takes "
                          + (f"{100 * c['share']:.0f} % of" if c["share"] < 1.0 else "all of") + " what is above "
                          f"the noise ({c['with_curve']:.2f} x left; {c['significance']:.0f} x what chance takes): a nonlinear "
                          "sensor or amplifier characteristic the catalogue "
                          "does not have" for c in curved)
                + f" ({now})")
    if disturbed:
        from .disturbance import describe  # disturbance measures with effective_samples, from here

        return "; ".join(describe(x) for x in disturbed) + ("" if limit is None else f"; {stopped}") + f" ({now})"
    if verdict == "unexplained" and local and within_noise(train, held):
        return (f"within {NOISE_MARGIN:g} x the noise on the whole, but {len(local)} windows of {LOCAL_WINDOW_S:g} s stand "
                f"more than {LOCAL_MARGIN:g} x above what noise and discretisation leave there: "
                + "; ".join(f"{w['channel']} in {w['recording']} at {w['t_start']:.2f}-{w['t_end']:.2f} s ({w['regime']}) "
                            f"{w['ratio']:.1f} x" for w in local[:3])
                + f"; no catalogue effect removes {100 * LOCAL_GAIN:.0f} % of it ({now})")
    lone = lone_channel(train, held)
    if verdict == "unexplained" and lone:
        return (f"within {NOISE_MARGIN:g} x the noise on the whole, but {lone[0]} stays {lone[1]:.2f} x its noise (more "
                f"than {LONE_CHANNEL:g} x): " + ("no catalogue effect earns its place there" if limit is None else stopped)
                + f" ({now}; refit nominal: {refit_train['noise_ratio']:.2f} x, {refit_held['noise_ratio']:.2f} x)")
    if verdict == "nothing_missing":
        return f"the nominal model, refit within tolerance, is within {NOISE_MARGIN:g} x the noise on every channel: {now}"
    if verdict == "explained":
        within = within_noise(train, held)
        return ((f"the findings bring the model within {NOISE_MARGIN:g} x the noise" if within else
                 f"the findings remove {100 * share:.0f} % of the validation residual above the noise (at least "
                 f"{100 * EXPLAINED_SHARE:.0f} % asked); "
                 + ("what is left no further catalogue effect explains" if limit is None else stopped))
                + f" ({now}; refit nominal: {refit_train['noise_ratio']:.2f} x, {refit_held['noise_ratio']:.2f} x)")
    return (f"the residual stays above {NOISE_MARGIN:g} x the noise ({now}; refit nominal: {refit_train['noise_ratio']:.2f} x, "
            f"{refit_held['noise_ratio']:.2f} x) and " + ("no further catalogue effect earns its place" if limit is None else stopped)
            + ": see 'residual'")
