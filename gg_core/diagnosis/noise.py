"""Position noise of observed garment sequences: the error model of registered meshes (neighbouring vertices err
together, a registration shifts whole patches, independently from frame to frame), an estimate of its level from
the data alone, and the temporal smoothing the diagnosis applies when that level is high.

Why smoothing matters: the simulator's step reads the velocity (x_t - x_{t-1}) fps and is judged on x_{t+1}, so
independent noise of std sigma on every frame correlates the observed acceleration with the observed velocity by
-3 sigma^2 fps^3. Any damping term then fits that correlation: measured on the benchmark's skirt with 1.5 mm noise,
an apparent mass damping of 12-32 /s (the reference cloth has 1 /s), against 0.05-1.8 /s after a 9-frame cubic
Savitzky-Golay filter, which itself biases damping by at most -0.3 /s on noise-free data.
"""
from __future__ import annotations

import numpy as np
from scipy.signal import savgol_coeffs, savgol_filter
from scipy.sparse import coo_matrix
from scipy.spatial import cKDTree

SMOOTH_WINDOW = 9        # frames of the longest Savitzky-Golay filter: SMOOTH_WINDOW // 2 are dropped at each end
SMOOTH_ORDER = 3         # of the default filter (SMOOTH_WINDOW frames, cubic)
# (window, order) candidates, chosen per sequence by choose_filter. Measured on `none` s5 at 1.5 mm noise
# (/work/data/s70/scratch/sg_choice.py): the walk's legs kick the hem faster than a 9-frame cubic follows (it alone
# moves the noise-free walk 1.17 mm, the twist and arm swing 0.2 mm), so on the walk 9 / 3 leaves 40 mm/s of
# velocity error and 9 / 5 27 mm/s; on the twist and arm swing 9 / 3 stays best (15 mm/s, 9 / 5 24 mm/s).
FILTERS = ((5, 3), (7, 3), (9, 3), (7, 5), (9, 5))
# What smoothing leaves (session 69, /work/data/s69/simex): velocity errors of 25-35 mm/s rms at 1.5 mm noise against
# 80-150 mm/s of motion on the benchmark skirt. Fits that predict a few frames ahead of observed states absorb them in
# the material (errors in variables): the baseline's membrane stiffness per mass mu / density came out 0.57x the
# clean fit's on `none` s5. Predicting 6 frames ahead instead of 3 (a parameter's effect grows as k^2, a velocity
# error's as k) brought it to 0.88x, but measured end to end and not kept: air damping s5 at 1.5 mm delivered alpha
# 85 % off (82.6 % at 3 frames; the folds' 16 / 31 / 18 /s), -24.2 % over the folds (-27.5 %); `none` s5 stayed none.


def correlated_noise(template: np.ndarray, sigma: float, length: float, n_frames: int,
                     rng: np.random.Generator) -> np.ndarray:
    """[T,V,3] noise with standard deviation `sigma` (m) per coordinate and a Gaussian spatial correlation of
    length `length` (m) over the template: white noise smoothed by a truncated Gaussian kernel (3 lengths),
    each vertex rescaled to the exact standard deviation."""
    pairs = cKDTree(template).query_pairs(3 * length, output_type="ndarray")
    n = len(template)
    i = np.r_[pairs[:, 0], pairs[:, 1], np.arange(n)]
    j = np.r_[pairs[:, 1], pairs[:, 0], np.arange(n)]
    w = np.exp(-((template[i] - template[j]) ** 2).sum(1) / (2 * length ** 2))
    kernel = coo_matrix((w, (i, j)), shape=(n, n)).tocsr()
    scale = sigma / np.sqrt(np.asarray(kernel.multiply(kernel).sum(1)).ravel())
    white = rng.normal(size=(n, 3 * n_frames))
    return (scale[:, None] * (kernel @ white)).reshape(n, n_frames, 3).transpose(1, 0, 2)


def noise_level(positions: np.ndarray) -> float:
    """Per-coordinate standard deviation (m) of frame-independent noise on [T,V,3] positions (T >= 4).

    The third time difference of smooth motion is small, that of independent noise has variance 20 sigma^2; the
    median absolute value (x 1.4826 for a Gaussian) ignores the few frames where the motion itself jerks
    (contacts). Measured on the benchmark skirt: 0.03-0.2 mm without noise, 1.54 mm with 1.5 mm noise."""
    d3 = np.diff(positions, 3, axis=0)
    return float(1.4826 * np.median(np.abs(d3)) / np.sqrt(20.0))


def smooth_in_time(positions: np.ndarray, window: int = SMOOTH_WINDOW, order: int = SMOOTH_ORDER) -> np.ndarray:
    """[T - 2h, V, 3] positions filtered along time by a Savitzky-Golay filter (`window` frames, polynomials of
    `order`; exact for such motion), kept where the longest candidate filter is centred: output frame k is input
    frame k + h, h = SMOOTH_WINDOW // 2, whichever filter a sequence gets (so every choice trims alike).

    Why the ends are dropped: there the filter extrapolates a polynomial and its velocity error is several times
    that of the centre; rollouts start from the first frames, and a wrong initial velocity field decays only
    under damping, so damping then looks right again (measured: with the ends kept, the benchmark's noisy `none`
    captures were diagnosed with material or linear damping, 14-25 % held-out gain)."""
    h = SMOOTH_WINDOW // 2
    if len(positions) < SMOOTH_WINDOW:
        raise ValueError(f"{len(positions)} frames are too few to smooth over {SMOOTH_WINDOW}")
    return savgol_filter(positions, window, order, axis=0, mode="interp")[h:len(positions) - h]


def choose_filter(positions: np.ndarray, sigma: float) -> tuple[int, int]:
    """The (window, order) of FILTERS with the least expected squared error against the noise-free motion, from
    the noisy positions alone: Stein's unbiased risk estimate for a linear smoother S with centre weight S_ii,
    mean |x - S x|^2 + sigma^2 (2 S_ii - 1) per coordinate (frame-independent noise of std `sigma`), over the frames
    every candidate centres. A long, low-order filter removes more noise but also motion it cannot follow
    (measured: the estimate tracks the error against the clean recording to 0.05 mm, FILTERS says where)."""
    h = SMOOTH_WINDOW // 2

    def risk(window: int, order: int) -> float:
        residual = positions[h:len(positions) - h] - smooth_in_time(positions, window, order)
        return float((residual ** 2).mean()) + sigma ** 2 * (2 * savgol_coeffs(window, order)[window // 2] - 1)

    return min(FILTERS, key=lambda f: risk(*f))


def noise_replicas(positions: np.ndarray, count: int, rng: np.random.Generator, window: int = SMOOTH_WINDOW,
                   order: int = SMOOTH_ORDER) -> list[np.ndarray]:
    """`count` copies of smooth_in_time(positions + d, window, order), d a fresh draw of noise like the positions'
    own: what the smoothed recording would be with twice its noise variance (TeacherForced extrapolates its loss to
    none).

    Why resampled residuals and not correlated_noise: a registration's errors have their own spatial pattern and
    level, which the data show and no parameter says. The smoothing's residual (positions minus smoothed, at the
    centred frames) is the noise passed through I - P, P the filter's projection, so its variance per frame is the
    noise's times 1 - P_ii (P_ii the filter's centre weight) with the spatial correlation untouched; its frames,
    drawn with replacement, signs flipped at random and rescaled by 1 / sqrt(1 - P_ii), are noise independent from
    frame to frame with the observed spatial covariance (plus the little motion the filter misses).

    Measured (session 70, one replica, filters 9 / 3, /work/data/s70): the baseline on `none` s5 at 1.5 mm came out
    with mu / density 1.22e6 against 0.75e6 without and 1.31e6 on clean data, but with two or four replicas 0.95e6 /
    1.92e6 (the material ratios are poorly determined); end to end air damping s5 at 1.5 mm delivered alpha 78.1 %
    off (82.6 % without; the folds' 17.9 / 21.7 / 18.3 /s) and gained -24.0 % over the folds (-27.5 %), `none` s5
    stayed none. Smoothing itself, not the noise it leaves, holds the alpha up: a refit of material and alpha from
    10 /s on clean recordings ends at 10.0 /s unsmoothed and 15.0 /s smoothed (session 69, simex/ad5.log). So the
    diagnosis fits without replicas by default (DiagnoseRequest.noise_replicas)."""
    h = SMOOTH_WINDOW // 2
    smoothed = smooth_in_time(positions, window, order)
    residual = positions[h:len(positions) - h] - smoothed
    residual = residual / np.sqrt(1.0 - savgol_coeffs(window, order)[window // 2])
    out = []
    for _ in range(count):
        draw = rng.integers(0, len(residual), len(positions))
        sign = rng.choice((-1.0, 1.0), len(positions))
        out.append(smoothed + smooth_in_time(residual[draw] * sign[:, None, None], window, order))
    return out
