"""Selection: which screened candidates a round fits in full, and which of them first.

Contract: `shortlist(ranked)` takes the candidates ranked by screening gain (screening.screen; `checked` set by
rescreen.rescreen where it simulated them) and names those to fit in full (effect_fit.fit_candidate): the leaders, a
tie, what the simulations put close, a simpler and a rival law at the leader's place and one cheap candidate
elsewhere. `leader_first(top)` splits that list into the candidates fitted first and those fitted only when the
first leave the round outside the noise (pipeline). Neither simulates: both read the gains the screening and the
rescreen left.
"""
from __future__ import annotations

from .screening import CURVE_LAWS, MIN_GAIN, Candidate

SCREEN_TOP = 2  # candidates fitted in full after the signature screening (one per worker)
SCREEN_TIE = 0.95  # ... and any more that screen within 5 % of the last of those: a tie in the
SCREEN_MAX = 4  # screening is no evidence (up to this many; friction laws often screen alike)
SCREEN_FLOOR = 0.1  # a runner-up whose screening and simulated gains are both below this share of the leader's is not
# fitted: the linear picture misjudges stick-slip by 2x (a Coulomb friction screened at 21 % against Stribeck's 41 %,
# fitted better), not by 10x, and it is the costly fits (a ripple's period scan) that such runners-up take (seed 114,
# laser_arm-2996f539: a motor-current gain screened at 15 %, a hub ripple at 1.1 % and simulated at 0.06 %, 500 of
# the round's 657 simulations; a later round screens again with the leader in)
LEADER_FIRST = 0.6  # a runner-up elsewhere screened and simulated below this share of the leader's is fitted only
# when the leader's fit leaves the round outside the noise (leader_first): seed 115, watflex-50ef1468, a 7 ms command
# delay screened at 66 %, an elbow ripple, dwell-time stiction and Stribeck friction at 33-35 %, whose scans took 288 s
# of the case's 389 s and which fitted to 7.2-8.8 x the noise on validation against the delay's 0.90 x
SIMULATED_TIE = 0.8  # a candidate rescreen simulated at this share of the best listed one's gain is fitted too: it was
# simulated at a linear estimate, not at its best (seed 48, a laser beam 0.33 x as stiff: 70 % against the hub
# compliance's 86 %; fitted, it explains validation as well as the compliance, 0.876 against 0.880 x the noise)


def shortlist(ranked: list[Candidate], screen_top: int = SCREEN_TOP) -> list[Candidate]:
    """The candidates to fit in full, from those ranked by screening gain: the first `screen_top`
    that explain anything and screen or simulate at SCREEN_FLOOR at least of the first's gain (the less of its screened
    and simulated), any more (to SCREEN_MAX) within SCREEN_TIE of the last of them, and the
    best-screening simpler law at the leader's place (fewer parameters, a screening gain of at least
    what its parameters will be charged, MIN_GAIN each), a friction law's best-screening rival law (`rival_law`) and the
    best one-parameter candidate at another place (`elsewhere`).
    One that `rescreen` found worse than no effect at its estimate and half-way gives its place to the best it found
    better; the best one the simulations put within
    SIMULATED_TIE of the best listed one is fitted too (seed 44, a laser beam 0.39 x as stiff: the beam's stiffness
    screened third at 55 % and simulated first at 80 %, against 70-72 % for the hub's compliance and backlash, which
    were fitted, and the compliance was found). A signature is a linear picture and
    stick-slip is not: a laser hub's Coulomb friction in closed loop screened at 21 % against
    Stribeck's 41 %, then fitted to 0.75 x the noise on validation against Stribeck's 1.00 x."""
    lead = lead_gain(ranked[0]) if ranked else 0.0
    weak = lambda c: best_gain(c) < SCREEN_FLOOR * lead  # noqa: E731
    top = [c for c in ranked[:screen_top] if c.gain > 0 and not weak(c)]
    top += [c for c in ranked[screen_top:SCREEN_MAX] if top and c.gain >= SCREEN_TIE * top[-1].gain and not weak(c)]
    spare = sorted((c for c in ranked if c not in top and (c.checked or 0) > 0 and not weak(c)),
                   key=lambda c: -c.checked)
    top = [spare.pop(0) if c.checked is not None and c.checked < 0 and spare else c for c in top]
    checked = [c.checked for c in top if c.checked is not None]
    if spare and checked and spare[0].checked >= SIMULATED_TIE * max(checked):  # the simulation puts it close: fit it too
        top.append(spare.pop(0))
    simpler = [c for c in ranked if top and c not in top and c.where == top[0].where
               and len(c.slots) < len(top[0].slots) and c.gain >= MIN_GAIN * len(c.slots)]
    top += simpler[:1]
    top += rival_law(ranked, top)
    return top + elsewhere(ranked, top, lead)


def lead_gain(c: Candidate) -> float:
    """A leader's gain as its runners-up are judged against: the less of its screened and simulated gains (0 where
    its simulation found it worse than no effect)."""
    return c.gain if c.checked is None else min(c.gain, max(c.checked, 0.0))


def best_gain(c: Candidate) -> float:
    """A runner-up's gain as it is judged against a leader: the more of its screened and simulated gains."""
    return c.gain if c.checked is None else max(c.gain, c.checked)


def leader_first(top: list[Candidate], hidden: Candidate | None = None) -> tuple[list[Candidate], list[Candidate]]:
    """`top` (a shortlist) split into the candidates fitted first and those fitted only when none of the first leaves
    the round within the noise (pipeline): a runner-up at another place than the leader's whose screened and simulated
    gains are both below LEADER_FIRST x the leader's (`lead_gain`). Where the leader fits the data to within the noise
    on every channel such a runner-up can at most tie it, and a linear picture that put it that far behind has not
    been seen to misjudge it so (seeds 114-115: every round's winner screened at 0.95-1.44 x the leader, none of 20
    runners-up below 0.6 x won or was listed as an alternative; seed 44's winner simulated first at 1.1 x, seed
    48's at 0.81 x). Runners-up at the leader's place (a rival or simpler law: stick-slip is where the picture
    misjudges by 2 x, seed 48's Coulomb friction screened at 0.51 x a Stribeck's and fitted better) and `hidden`
    (what the refit took up) are fitted first."""
    if not top:
        return [], []
    lead = lead_gain(top[0])
    deferred = [c for c in top[1:] if c.where != top[0].where and c is not hidden
                and best_gain(c) < LEADER_FIRST * lead]
    return [c for c in top if c not in deferred], deferred


def elsewhere(ranked: list[Candidate], listed: list[Candidate], lead: float) -> list[Candidate]:
    """The best-screening one-parameter candidate at a place none of `listed` is at, screened and simulated at
    SCREEN_FLOOR of the leader's gain at least (`lead_gain`; a list of at most one). Rivals at one place crowd the
    shortlist (friction laws screen alike; a simpler and a rival law are added), and an actuator's gain, which a
    closed loop shows as more or less friction at its joint, screens below them and is never fitted (seed 116,
    watflex-e9576ce5: an elbow torque gain x0.759 beside an elbow ripple screened third at 22 %, then fifth at 36 %
    against viscous friction's 60 %; viscous friction was found in its place and 35 x the noise was left; fitted too,
    the gain wins round 2 and the case ends at 1.54 x, gain 0.757). One parameter: a fit of a few simulations, no
    scan; below LEADER_FIRST of the leader it waits until the round's first fits leave the noise (leader_first)."""
    places = {c.where for c in listed}
    return [c for c in ranked if c not in listed and c.where not in places and len(c.slots) == 1 and not c.periodic
            and not c.shape and lead_gain(c) > 0 and lead_gain(c) >= SCREEN_FLOOR * lead][:1]


def rival_law(ranked: list[Candidate], listed: list[Candidate]) -> list[Candidate]:
    """Where the leader of `listed` is a friction law (CURVE_LAWS) and no other is listed at its joint: the
    best-screening other law there that screens at MIN_GAIN per parameter, whatever `rescreen` simulated for it (a
    list of at most one). Friction laws at one joint are each other's nearest rivals and a signature, a linear
    picture of stick-slip, ranks them by chance (seed 86, laser_arm-4d9d7591, a hub Stribeck friction of break-away
    0.045 / 0.049 N m decaying by 0.024 rad/s: screened at 28 % and simulated at -13 % at its linear estimate beside
    the Coulomb friction's 87 % / 76 %, it was never fitted, and the Coulomb friction was named at 0.89 x the noise
    with no alternative given)."""
    leader = listed[0] if listed else None
    if leader is None or leader.effect not in CURVE_LAWS or any(
            c.effect in CURVE_LAWS and c.where == leader.where for c in listed[1:]):
        return []
    return [c for c in ranked if c not in listed and c.effect in CURVE_LAWS and c.where == leader.where
            and c.gain >= MIN_GAIN * len(c.slots)][:1]
