"""Shared test models: a clamped-free flexible beam built with the project's own chain builder."""
from __future__ import annotations

import mujoco
import pytest

from watflex_sim.build import add_flexible_chain, chain_tip_x


def build_cantilever(beam, n_segments: int, tip_mass: float = 0.0) -> mujoco.MjModel:
    """A clamped-free beam: `add_flexible_chain` on a fixed body, no gravity.

    The free end (x = dx/2 in the last chain body, `chain_tip_x`) carries a body `tip_point`
    with a site `tip` and, if `tip_mass` > 0 (kg), a point mass (a 0.1 mm sphere: rotary
    inertia 0.4 m r^2 = 4e-9 kg m^2 per kg, negligible). With a mass the body's centre of mass is the tip, so
    `xfrc_applied` on it is a force at the tip.
    """
    spec = mujoco.MjSpec()
    spec.option.gravity = [0, 0, 0]
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    base = spec.worldbody.add_body(name="clamp")
    last = add_flexible_chain(base, "beam", beam, n_segments, 0.0)
    tip = last.add_body(name="tip_point", pos=[chain_tip_x(beam, n_segments), 0, 0])
    if tip_mass > 0:
        g = tip.add_geom(name="tip_mass", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[1e-4, 0, 0])
        g.mass = tip_mass
        g.contype = g.conaffinity = 0
    tip.add_site(name="tip")
    return spec.compile()


@pytest.fixture
def cantilever():
    """Factory fixture: `cantilever(beam, n_segments, tip_mass)` -> MjModel (see build_cantilever)."""
    return build_cantilever
