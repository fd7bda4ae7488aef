"""A slow reference of another formulation for the rod in motion: a planar discrete elastica.

The rod (clamped at the base along +z, bending in the x-z plane) is a chain of ``links`` rigid
links of length h with absolute angles phi_k from the z axis, its mass lumped at the joints
(rho A h each, half at the tip), bending springs E I / h between neighbouring links and 2 E I / h
to the clamp, gravity -g z. Lagrange's equations

    M(phi) phi'' + C(phi) phi'^2 = -dV/dphi,
    M_jk = h^2 cos(phi_j - phi_k) sum_{i >= max(j,k)} m_i

(C_jk = h^2 sin(phi_j - phi_k) sum_{i >= max(j,k)} m_i) are integrated by classical RK4. It
ignores shear, extension and rotary inertia, which the Cosserat rod has but a slender Nitinol
rod barely feels; it converges as 1 / links^2.
"""
import numpy as np
from scipy.optimize import root


class Chain:
    """The discrete elastica of a rod: ``length`` (m), ``ei`` (N m^2), ``rho_a`` (kg/m)."""

    def __init__(self, length, ei, rho_a, gravity, links):
        self.h = length / links
        self.k = ei / self.h
        masses = np.full(links, rho_a * self.h)
        masses[-1] *= 0.5
        # sum of the masses at joint i and beyond, for each pair: beyond[max(j, k)]
        beyond = np.cumsum(masses[::-1])[::-1]
        index = np.arange(links)
        self.beyond = beyond[np.maximum.outer(index, index)]
        self.masses, self.g = masses, gravity
        self.weight_beyond = beyond * gravity  # N: the weight each link's joint carries

    def _forces(self, phi, tip_force):
        """-dV/dphi (N m per rad): springs, gravity and a tip force (fx, fz)."""
        bend = np.diff(np.concatenate([[0.0], phi]))
        # the clamp's spring spans half a link (0 to h / 2): twice as stiff; the chain then
        # converges as 1 / links^2 (with E I / h there too, as 1 / links)
        moments = self.k * bend
        moments[0] *= 2.0
        spring = -moments
        spring[:-1] += moments[1:]
        # joint i sits at sum_{k <= i} h (sin phi_k, cos phi_k): link k lifts every mass beyond
        gravity = self.weight_beyond * self.h * np.sin(phi)
        tip = self.h * (tip_force[0] * np.cos(phi) - tip_force[1] * np.sin(phi))
        return spring + gravity + tip

    def rest(self, tip_force):
        """Angles (links,) of the static equilibrium under ``tip_force`` (fx, fz) (N)."""
        guess = np.zeros(len(self.masses))
        result = root(lambda phi: self._forces(phi, tip_force), guess, tol=1e-13)
        assert np.max(np.abs(self._forces(result.x, tip_force))) < 1e-12 * self.k, result
        return result.x

    def tip(self, phi):
        """Tip (x, z) (m) of angles ``phi`` (..., links)."""
        return self.h * np.stack([np.sin(phi).sum(-1), np.cos(phi).sum(-1)], axis=-1)

    def motion(self, phi0, times):
        """Angles at ``times`` (s, multiples of the step) released at rest from ``phi0``.

        Classical RK4 at a fixed step below its stability limit on the chain's stiffest mode,
        omega_max ~ (2 / h)^2 sqrt(E I / rho A) (the links' own vibration).
        """
        n = len(phi0)

        def rates(phi, omega):
            difference = phi[:, None] - phi[None, :]
            mass = self.h ** 2 * np.cos(difference) * self.beyond
            coriolis = self.h ** 2 * np.sin(difference) * self.beyond @ (omega ** 2)
            return omega, np.linalg.solve(mass, self._forces(phi, (0.0, 0.0)) - coriolis)

        stiffest = (2.0 / self.h) ** 2 * np.sqrt(self.k * self.h / self.masses[0] * self.h)
        dt = 1.0 / stiffest  # RK4 is stable to 2.8 / omega
        phi, omega = np.array(phi0, dtype=float), np.zeros(n)
        out, t = [], 0.0
        for target in times:
            steps = max(1, int(np.ceil((target - t) / dt)))
            h = (target - t) / steps
            for _ in range(steps):
                a1, b1 = rates(phi, omega)
                a2, b2 = rates(phi + 0.5 * h * a1, omega + 0.5 * h * b1)
                a3, b3 = rates(phi + 0.5 * h * a2, omega + 0.5 * h * b2)
                a4, b4 = rates(phi + h * a3, omega + h * b3)
                phi = phi + h / 6.0 * (a1 + 2.0 * (a2 + a3) + a4)
                omega = omega + h / 6.0 * (b1 + 2.0 * (b2 + b3) + b4)
            t = target
            out.append(phi.copy())
        return np.array(out)
