"""The spectral normal integrations of a full rectangular normal map: ``"dct"`` (Simchony,
Chellappa & Shao 1990) and ``"fc"`` (Frankot & Chellappa 1988), for
:func:`irtps.geometry.integrate.integrate_normals`.
"""

from __future__ import annotations

import numpy as np
import scipy.fft


def integrate_dct(gc, gr):
    """Least squares on the full grid: Neumann Poisson equation, exact by DCT-II."""
    h, w = gc.shape
    # Edge targets (average of forward and backward): the normal equations are L z = -div g.
    ec = 0.5 * (gc[:, :-1] + gc[:, 1:])
    er = 0.5 * (gr[:-1, :] + gr[1:, :])
    b = np.zeros((h, w))
    b[:, 1:] += ec
    b[:, :-1] -= ec
    b[1:, :] += er
    b[:-1, :] -= er
    # L is the graph Laplacian of the grid (Neumann), diagonal in the orthonormal DCT-II basis.
    lam_r = 2.0 - 2.0 * np.cos(np.pi * np.arange(h) / h)
    lam_c = 2.0 - 2.0 * np.cos(np.pi * np.arange(w) / w)
    lam = lam_r[:, None] + lam_c[None, :]
    lam[0, 0] = 1.0
    bh = scipy.fft.dctn(b, type=2, norm="ortho")
    zh = bh / lam
    zh[0, 0] = 0.0
    return scipy.fft.idctn(zh, type=2, norm="ortho")


def integrate_fc(gc, gr):
    """Frankot-Chellappa: least-squares projection onto periodic integrable surfaces."""
    h, w = gc.shape
    wc = 2.0 * np.pi * scipy.fft.fftfreq(w)[None, :]
    wr = 2.0 * np.pi * scipy.fft.fftfreq(h)[:, None]
    gch = scipy.fft.fft2(gc)
    grh = scipy.fft.fft2(gr)
    denom = wc * wc + wr * wr
    denom[0, 0] = 1.0
    zh = (-1j * wc * gch - 1j * wr * grh) / denom
    zh[0, 0] = 0.0
    return np.real(scipy.fft.ifft2(zh))
