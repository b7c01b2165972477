"""Normalized Gaussian basis functions over the phase z in [0, 1] (thesis eqs. 1 and 15).

Past the end of the movement (z > 1) the person holds still, so the basis is clamped: psi(z) =
psi(1) and every derivative is zero there (likewise before z = 0).
"""

import numpy as np


class GaussianBasis:
    """``n_basis`` normalized Gaussians, centres evenly spread over [0, 1].

    ``width`` is the standard deviation of each Gaussian in phase units; by default it equals the
    centre spacing, which keeps neighbours overlapping so any smooth path is representable.
    """

    def __init__(self, n_basis: int = 15, width: float | None = None):
        if int(n_basis) != n_basis or n_basis < 2:
            raise ValueError(f'n_basis must be an integer >= 2, got {n_basis!r}')
        self.n_basis = int(n_basis)
        self.centers = np.linspace(0.0, 1.0, self.n_basis)
        spacing = 1.0 / (self.n_basis - 1)
        self.width = float(spacing if width is None else width)
        if not np.isfinite(self.width) or self.width <= 0:
            raise ValueError(f'width must be a positive number, got {width!r}')

    def to_dict(self) -> dict:
        return {'n_basis': self.n_basis, 'width': self.width}

    @classmethod
    def from_dict(cls, d: dict) -> 'GaussianBasis':
        return cls(int(d['n_basis']), float(d['width']))

    def __eq__(self, other):
        return (isinstance(other, GaussianBasis) and self.n_basis == other.n_basis
                and self.width == other.width)

    def gram(self) -> np.ndarray:
        """M = integral over z in [0, 1] of psi(z) psi(z)^T (n_basis, n_basis): the metric of
        paths in weight space, (w1 - w2)^T M (w1 - w2) the mean squared distance between the
        paths psi^T w1 and psi^T w2 over the phase. Gauss-Legendre quadrature, exact to
        rounding for these smooth functions."""
        nodes, weights = np.polynomial.legendre.leggauss(8 * self.n_basis + 32)
        z = 0.5 * (nodes + 1.0)
        psi = self(z)
        return (psi * (0.5 * weights)[:, None]).T @ psi

    def __call__(self, z) -> np.ndarray:
        """psi(z) of eq. 15: shape (len(z), n_basis); rows sum to one."""
        return self.evaluate(z, order=0)[0]

    def evaluate(self, z, order: int = 2):
        """psi and its derivatives with respect to z, up to ``order`` (0, 1 or 2).

        Returns a tuple of arrays of shape (len(z), n_basis). Time derivatives follow from
        z = alpha (t - t0): d/dt = alpha d/dz.
        """
        z = np.atleast_1d(np.asarray(z, dtype=float))
        if z.ndim != 1:
            raise ValueError(f'z must be a scalar or 1-D array, got shape {z.shape}')
        if not np.all(np.isfinite(z)):
            raise ValueError('phase z contains NaN or Inf')
        inside = ((z >= 0.0) & (z <= 1.0))[:, None]
        zc = np.clip(z, 0.0, 1.0)[:, None]
        h = self.width ** 2
        d = zc - self.centers[None, :]
        b = np.exp(-0.5 * d * d / h)
        s = b.sum(axis=1, keepdims=True)
        psi = b / s
        out = [psi]
        if order >= 1:
            db = -b * d / h
            ds = db.sum(axis=1, keepdims=True)
            dpsi = (db - psi * ds) / s
            out.append(np.where(inside, dpsi, 0.0))
            if order >= 2:
                ddb = b * (d * d / (h * h) - 1.0 / h)
                dds = ddb.sum(axis=1, keepdims=True)
                ddpsi = (ddb - 2.0 * dpsi * ds - psi * dds) / s
                out.append(np.where(inside, ddpsi, 0.0))
        return tuple(out)
