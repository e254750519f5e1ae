"""Frequency and damping ratio of a free decay: FFT peak, half-power, log decrement, matrix pencil.

Every estimator takes a record y(t) [any unit] with real timestamps [s] and returns the natural
frequency f_n [Hz] and damping ratio ζ of one mode, y ≈ A e^(−ζ ω_n τ) cos(ω_n √(1−ζ²) τ + φ),
each with a one-sigma uncertainty (method notes, "Damping").
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy import signal
from scipy.fft import next_fast_len, rfft, rfftfreq
from scipy.optimize import least_squares
from sds_model.errors import InputError

RESOLUTION_SIGMA = 1.0 / (2.0 * np.sqrt(3.0))
"""One-sigma error of a frequency read off a spectrum, in units of its resolution 1/T
(a uniform error within ± half a bin)."""
RECTANGULAR_HALF_POWER_WIDTH = 0.886
"""−3 dB full width of the rectangular window's main lobe, in units of 1/T."""
MIN_EXTREMA = 4
DECREMENT_FLOOR = 0.05
"""The log decrement stops at the first extremum below 5 % of the first (about 3 e-folds):
the rest is mostly noise, which flattens the fitted decay."""
MIN_SAMPLES = 16


class DecayError(InputError):
    """A record that cannot give the asked estimate; the message says why."""


@dataclass(frozen=True)
class ModeEstimate:
    """One estimator's natural frequency and damping ratio of one mode, with one-sigma errors.

    `damping_ratio` is NaN where the method gives none; `note` says when a value sits at the
    method's resolution limit or was not found.
    """

    method: str
    frequency_hz: float
    frequency_sigma_hz: float
    damping_ratio: float
    damping_ratio_sigma: float
    amplitude: float
    window_start_s: float
    window_end_s: float
    note: str = ""

    def as_dict(self) -> dict[str, Any]:
        """Plain JSON-ready dictionary."""
        return asdict(self)


@dataclass(frozen=True)
class DampedSinusoid:
    """One component e^(−α τ) (a cos ω τ + b sin ω τ), τ = t − start [s], with its covariance."""

    decay_rate_s: float            # α [1/s]
    angular_frequency_rad_s: float  # ω_d [rad/s]
    cos_amplitude: float
    sin_amplitude: float
    covariance: np.ndarray          # of (α, ω_d) [1/s², rad²/s²]

    @property
    def natural_frequency_hz(self) -> float:
        """f_n = √(ω_d² + α²) / 2π."""
        return float(np.hypot(self.angular_frequency_rad_s, self.decay_rate_s) / (2 * np.pi))

    @property
    def damping_ratio(self) -> float:
        """ζ = α / ω_n."""
        return float(self.decay_rate_s / np.hypot(self.angular_frequency_rad_s, self.decay_rate_s))

    @property
    def amplitude(self) -> float:
        """Amplitude at the window start √(a² + b²)."""
        return float(np.hypot(self.cos_amplitude, self.sin_amplitude))

    def sigmas(self) -> tuple[float, float]:
        """One-sigma errors of f_n [Hz] and ζ by first-order propagation of the covariance."""
        alpha, omega = self.decay_rate_s, self.angular_frequency_rad_s
        omega_n = np.hypot(omega, alpha)
        grad_f = np.array([alpha, omega]) / (2 * np.pi * omega_n)
        grad_zeta = np.array([omega**2, -alpha * omega]) / omega_n**3
        return (float(np.sqrt(grad_f @ self.covariance @ grad_f)),
                float(np.sqrt(grad_zeta @ self.covariance @ grad_zeta)))

    def evaluate(self, tau_s: ArrayLike) -> np.ndarray:
        """The component's value at τ [s] after the window start."""
        tau = np.asarray(tau_s, dtype=float)
        phase = self.angular_frequency_rad_s * tau
        return np.exp(-self.decay_rate_s * tau) * (self.cos_amplitude * np.cos(phase)
                                                   + self.sin_amplitude * np.sin(phase))

    def norm(self, tau_s: ArrayLike) -> float:
        """√(Σ c(τ)²) over the samples at τ [s]: how much of the record the component is."""
        return float(np.sqrt(np.sum(self.evaluate(tau_s) ** 2)))


@dataclass(frozen=True)
class DampedSinusoidFit:
    """Offset plus damped sinusoids fitted to a record from `start_s` (matrix pencil + NLS),
    the components largest in the window first (`window_norm`)."""

    start_s: float
    end_s: float
    offset: float
    components: tuple[DampedSinusoid, ...]
    residual_rms: float
    sample_tau_s: np.ndarray      # the samples' times after `start_s` [s]
    bic: float

    def evaluate(self, time_s: ArrayLike) -> np.ndarray:
        """The fitted model at times [s]."""
        tau = np.asarray(time_s, dtype=float) - self.start_s
        return self.offset + sum((c.evaluate(tau) for c in self.components), np.zeros_like(tau))

    def window_norm(self, component: DampedSinusoid) -> float:
        """√(Σ c(τ)²) of a component over the window's samples."""
        return component.norm(self.sample_tau_s)

    def estimate(self, component: DampedSinusoid, method: str = "matrix_pencil") -> ModeEstimate:
        """A component as a `ModeEstimate`."""
        frequency_sigma, damping_sigma = component.sigmas()
        return ModeEstimate(method, component.natural_frequency_hz, frequency_sigma,
                            component.damping_ratio, damping_sigma, component.amplitude,
                            self.start_s, self.end_s)


def finite_window(time_s: ArrayLike, values: ArrayLike, start_s: float | None = None,
                  end_s: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The finite samples within [start, end] [s]; checks that time increases."""
    t, y = np.asarray(time_s, dtype=float), np.asarray(values, dtype=float)
    if t.shape != y.shape or t.ndim != 1:
        raise DecayError(f"time and values must be 1-D of one length, got {t.shape}, {y.shape}")
    keep = np.isfinite(t) & np.isfinite(y)
    if start_s is not None:
        keep &= t >= start_s
    if end_s is not None:
        keep &= t <= end_s
    t, y = t[keep], y[keep]
    if len(t) < MIN_SAMPLES:
        raise DecayError(f"{len(t)} finite samples in the window; {MIN_SAMPLES} or more needed")
    if np.any(np.diff(t) <= 0):
        raise DecayError("timestamps must increase strictly")
    return t, y


def uniform_record(time_s: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Resample onto the median step by linear interpolation (fills dropped frames)."""
    step = float(np.median(np.diff(time_s)))
    grid = time_s[0] + step * np.arange(round((time_s[-1] - time_s[0]) / step) + 1)
    return grid, np.interp(grid, time_s, values), step


def free_decay_start(time_s: ArrayLike, values: ArrayLike) -> float:
    """Start of the free decay after an impulsive excitation: the largest |y − median| [s]."""
    t, y = finite_window(time_s, values)
    return float(t[np.argmax(np.abs(y - np.median(y)))])


def excitation_onset(time_s: ArrayLike, values: ArrayLike, threshold: float = 8.0,
                     samples: int = 5) -> float:
    """First time [s] the record leaves its rest level: `samples` in a row beyond `threshold`
    robust sigmas (1.4826 MAD) of the rest, the samples before the largest swing."""
    t, y = finite_window(time_s, values)
    peak = int(np.argmax(np.abs(y - np.median(y))))
    if peak < MIN_SAMPLES:
        raise DecayError(f"{peak} samples before the largest swing; {MIN_SAMPLES} needed as rest")
    rest = y[:peak]
    level = np.median(rest)
    sigma = 1.4826 * np.median(np.abs(rest - level))
    outside = np.abs(y - level) > threshold * max(sigma, np.finfo(float).tiny)
    sustained = np.convolve(outside, np.ones(samples, dtype=int), "valid") == samples
    if not sustained.any():
        raise DecayError("the record never leaves its rest level")
    return float(t[np.argmax(sustained)])


def amplitude_spectrum(time_s: np.ndarray, values: np.ndarray, window: str = "hann",
                       pad_factor: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """One-sided amplitude spectrum of the linearly detrended, windowed, zero-padded record."""
    _, y, step = uniform_record(time_s, values)
    taper = signal.get_window(window, len(y))
    length = next_fast_len(pad_factor * len(y))
    spectrum = 2.0 * np.abs(rfft(signal.detrend(y) * taper, length)) / taper.sum()
    return rfftfreq(length, step), spectrum


def _parabolic_peak(x: np.ndarray, y: np.ndarray, index: int) -> tuple[float, float]:
    """Vertex of the parabola through three samples around `index`."""
    if index == 0 or index == len(y) - 1:
        return float(x[index]), float(y[index])
    left, centre, right = y[index - 1], y[index], y[index + 1]
    denominator = left - 2 * centre + right
    shift = 0.5 * (left - right) / denominator if denominator < 0 else 0.0
    return (float(x[index] + shift * (x[1] - x[0])),
            float(centre - 0.25 * (left - right) * shift))


def fft_peaks(time_s: ArrayLike, values: ArrayLike, count: int = 2, min_hz: float = 0.0,
              start_s: float | None = None, end_s: float | None = None) -> list[ModeEstimate]:
    """The `count` highest peaks of the Hann spectrum, interpolated (log-parabola), by height.

    The error is the spectrum's resolution, RESOLUTION_SIGMA / T: the FFT cannot separate a
    damped peak's position better than its bin on a short record.
    """
    t, y = finite_window(time_s, values, start_s, end_s)
    freqs, amplitude = amplitude_spectrum(t, y)
    duration = t[-1] - t[0]
    log_amplitude = np.log(np.maximum(amplitude, np.finfo(float).tiny))
    peaks, _ = signal.find_peaks(amplitude)
    peaks = peaks[freqs[peaks] > max(min_hz, 1.0 / duration)]
    peaks = peaks[np.argsort(amplitude[peaks])[::-1][:count]]
    estimates = []
    for peak in peaks:
        frequency, log_height = _parabolic_peak(freqs, log_amplitude, int(peak))
        estimates.append(ModeEstimate("fft_peak", frequency, float(RESOLUTION_SIGMA / duration),
                                      float("nan"), float("nan"), float(np.exp(log_height)),
                                      float(t[0]), float(t[-1])))
    return estimates


def half_power(time_s: ArrayLike, values: ArrayLike, frequency_hz: float,
               start_s: float | None = None, end_s: float | None = None) -> ModeEstimate:
    """ζ = (f₂ − f₁) / 2f₀ from the −3 dB points of the peak near `frequency_hz`.

    Rectangular window (the decay tapers itself). The width cannot be below the window's own,
    0.886 / T, so ζ below 0.443 / (f₀ T) is not measurable and says so in `note`; another peak
    inside the half-power band (close modes) gives NaN.
    """
    t, y = finite_window(time_s, values, start_s, end_s)
    duration = t[-1] - t[0]
    freqs, amplitude = amplitude_spectrum(t, y, window="boxcar")
    power = amplitude**2
    search = np.abs(freqs - frequency_hz) <= 1.0 / duration
    if not search.any():
        raise DecayError(f"{frequency_hz:.3f} Hz is outside the spectrum")
    peak = int(np.flatnonzero(search)[np.argmax(power[search])])
    f0, _ = _parabolic_peak(freqs, np.log(np.maximum(power, np.finfo(float).tiny)), peak)
    edges = []
    for direction in (-1, 1):
        index = peak
        while 0 < index < len(power) - 1 and power[index] > power[peak] / 2:
            if power[index + direction] > power[index]:   # climbing again: another mode
                index = -1
                break
            index += direction
        if index <= 0 or index >= len(power) - 1:
            edges.append(float("nan"))
            continue
        inner = index - direction
        fraction = (power[inner] - power[peak] / 2) / (power[inner] - power[index])
        edges.append(float(freqs[inner] + fraction * (freqs[index] - freqs[inner])))
    zeta = (edges[1] - edges[0]) / (2 * f0)
    sigma = np.sqrt(2.0) * RESOLUTION_SIGMA / duration / (2 * f0)
    limit = RECTANGULAR_HALF_POWER_WIDTH / (2 * f0 * duration)
    if not np.isfinite(zeta):
        note = "another peak inside the half-power band"
    elif zeta < 2 * limit:
        note = f"at the resolution limit (window alone gives ζ = {limit:.3f})"
    else:
        note = ""
    return ModeEstimate("half_power", f0, float(RESOLUTION_SIGMA / duration), float(zeta),
                        float(sigma), float(np.sqrt(power[peak])), float(t[0]), float(t[-1]),
                        note)


def _extrema(time_s: np.ndarray, values: np.ndarray, period_s: float
             ) -> tuple[np.ndarray, np.ndarray]:
    """Alternating maxima and minima (parabola-refined): times [s] and |values|."""
    step = float(np.median(np.diff(time_s)))
    distance = max(1, int(0.6 * period_s / 2 / step))
    found = []
    for sign in (1.0, -1.0):
        peaks, _ = signal.find_peaks(sign * values, distance=distance)
        found += [(*_parabolic_peak(time_s, sign * values, int(p)), sign) for p in peaks]
    found.sort()
    times: list[float] = []
    heights: list[tuple[float, float]] = []   # height, sign (+1 maximum, -1 minimum)
    for when, height, sign in found:   # keep alternation: a max must follow a min
        if heights and sign == heights[-1][1]:
            if height > heights[-1][0]:
                times[-1], heights[-1] = when, (height, sign)
            continue
        times.append(when)
        heights.append((height, sign))
    return np.array(times), np.array([h for h, _ in heights])


def _line_fit(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Least-squares slope, intercept and the slope's standard error."""
    design = np.column_stack([x, np.ones_like(x)])
    coefficients, residual, *_ = np.linalg.lstsq(design, y, rcond=None)
    dof = len(x) - 2
    variance = float(residual[0]) / dof if residual.size and dof > 0 else 0.0
    slope_variance = variance / float(np.sum((x - x.mean()) ** 2))
    return float(coefficients[0]), float(coefficients[1]), float(np.sqrt(slope_variance))


def log_decrement(time_s: ArrayLike, values: ArrayLike, frequency_hz: float,
                  bandwidth: float = 0.35, start_s: float | None = None,
                  end_s: float | None = None) -> ModeEstimate:
    """Exponential fit through the extrema of the band-passed decay: ln|y_k| = c − α t_k.

    Band-pass f(1 ± `bandwidth`) (4th-order Butterworth, zero phase); the extrema within one
    period of either end (the filter's edge transients) and those after the decay has faded
    below DECREMENT_FLOOR are left out. The damped period comes
    from the extrema's spacing; errors from both regressions' residuals.
    """
    t, y = finite_window(time_s, values, start_s, end_s)
    grid, uniform, step = uniform_record(t, y)
    nyquist = 0.5 / step
    band = [frequency_hz * (1 - bandwidth), min(frequency_hz * (1 + bandwidth), 0.95 * nyquist)]
    if band[0] <= 0 or band[0] >= band[1]:
        raise DecayError(f"no pass band around {frequency_hz:.3f} Hz at {1 / step:.1f} Hz sampling")
    sos = signal.butter(2, band, btype="bandpass", fs=1.0 / step, output="sos")
    filtered = signal.sosfiltfilt(sos, uniform - uniform.mean())
    period = 1.0 / frequency_hz
    times, heights = _extrema(grid, filtered, period)
    inner = (times > grid[0] + period) & (times < grid[-1] - period) & (heights > 0)
    times, heights = times[inner], heights[inner]
    if len(heights):
        faded = np.flatnonzero(heights < DECREMENT_FLOOR * heights[0])
        stop = faded[0] if len(faded) else len(heights)
        times, heights = times[:stop], heights[:stop]
    if len(times) < MIN_EXTREMA:
        raise DecayError(f"{len(times)} extrema away from the ends; {MIN_EXTREMA} needed")
    half_period, _, half_period_sigma = _line_fit(np.arange(len(times), dtype=float), times)
    slope, intercept, slope_sigma = _line_fit(times - times[0], np.log(heights))
    alpha, omega = -slope, np.pi / half_period
    covariance = np.diag([slope_sigma**2, (np.pi * half_period_sigma / half_period**2) ** 2])
    component = DampedSinusoid(alpha, omega, float(np.exp(intercept)), 0.0, covariance)
    frequency_sigma, damping_sigma = component.sigmas()
    return ModeEstimate("log_decrement", component.natural_frequency_hz, frequency_sigma,
                        component.damping_ratio, damping_sigma, component.amplitude,
                        float(t[0]), float(t[-1]))


MAX_PENCIL = 256
"""Largest pencil parameter L. Hua & Sarkar's N/3 is kept up to 768 samples (a 25 s window at
30 fps); beyond, the SVD's cost, O(N·L²), would grow as N³ (a 10-minute record: an hour) for
start poles that the least-squares fit refines anyway."""


def pencil_vectors(values: np.ndarray, order: int, pencil_fraction: float = 1.0 / 3.0
                   ) -> np.ndarray:
    """Right singular vectors (rows of Vᴴ, strongest first) of the record's Hankel data matrix,
    pencil parameter L = N·`pencil_fraction` (at least `order` + 1, at most MAX_PENCIL)."""
    count = len(values)
    pencil = max(order + 1, min(int(count * pencil_fraction), MAX_PENCIL))
    if count - pencil < order:
        raise DecayError(f"{count} samples are too few for {order} poles")
    rows = np.lib.stride_tricks.sliding_window_view(values, pencil + 1)
    return np.linalg.svd(rows, full_matrices=False)[2]


def pencil_poles(vectors: np.ndarray, step_s: float, order: int) -> np.ndarray:
    """Continuous-time poles s = −α ± iω_d of `order` exponentials from `pencil_vectors`."""
    if len(vectors) < order:
        raise DecayError(f"a pencil of {len(vectors)} is too small for {order} poles")
    basis = vectors[:order].T
    poles = np.linalg.eigvals(np.linalg.pinv(basis[:-1]) @ basis[1:])
    return np.log(poles.astype(complex)) / step_s


def _model_columns(tau: np.ndarray, rates: np.ndarray, omegas: np.ndarray) -> np.ndarray:
    """Design matrix: 1, then e^(−ατ) cos ωτ and e^(−ατ) sin ωτ per component."""
    with np.errstate(over="ignore"):
        envelope = np.exp(-np.outer(tau, rates))
    phase = np.outer(tau, omegas)
    columns = np.empty((len(tau), 1 + 2 * len(rates)))
    columns[:, 0] = 1.0
    columns[:, 1::2] = envelope * np.cos(phase)
    columns[:, 2::2] = envelope * np.sin(phase)
    return columns


def _nonlinear_columns(tau: np.ndarray, columns: np.ndarray, linear: np.ndarray,
                       count: int) -> np.ndarray:
    """∂(model)/∂(α₁, ω₁, …) of `_model_columns` · `linear` [one column per parameter]."""
    a, b = linear[1::2], linear[2::2]
    cos_part, sin_part = columns[:, 1::2], columns[:, 2::2]
    jac = np.empty((len(tau), 2 * count))
    with np.errstate(over="ignore", invalid="ignore"):
        jac[:, 0::2] = -tau[:, None] * (a * cos_part + b * sin_part)
        jac[:, 1::2] = tau[:, None] * (b * cos_part - a * sin_part)
    return np.nan_to_num(jac, nan=0.0, posinf=0.0, neginf=0.0)


class _VariableProjection:
    """Offset and amplitudes solved linearly for given rates and frequencies p = (α₁, ω₁, …):
    the residual and Kaufman's Jacobian in p alone. The last p's solution is kept, since
    the solver asks for the Jacobian where it has just asked for the residual."""

    def __init__(self, tau: np.ndarray, values: np.ndarray) -> None:
        self.tau = tau
        self.values = values
        self._last_p = b""
        self._last: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None] | None = None

    def at(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """Design matrix, least-squares amplitudes, residual and an orthonormal basis of the
        columns at p (None where the model overflows)."""
        if self._last is None or p.tobytes() != self._last_p:
            with np.errstate(over="ignore", invalid="ignore"):
                columns = _model_columns(self.tau, p[0::2], p[1::2])
            if not np.isfinite(columns).all():
                self._last = (columns, np.zeros(columns.shape[1]),
                              np.full(len(self.values), 1e12), None)
            else:
                basis, triangle = np.linalg.qr(columns)
                linear, *_ = np.linalg.lstsq(triangle, basis.T @ self.values, rcond=None)
                self._last = (columns, linear, columns @ linear - self.values, basis)
            self._last_p = p.tobytes()
        return self._last

    def residual(self, p: np.ndarray) -> np.ndarray:
        """Model minus record at p, the amplitudes solved."""
        return self.at(p)[2]

    def jacobian(self, p: np.ndarray) -> np.ndarray:
        """The residual's derivative in p, the amplitudes' change projected out (Kaufman)."""
        columns, linear, _, basis = self.at(p)
        if basis is None:
            return np.zeros((len(self.values), len(p)))
        derivative = _nonlinear_columns(self.tau, columns, linear, len(p) // 2)
        return derivative - basis @ (basis.T @ derivative)


def _fit_components(tau: np.ndarray, values: np.ndarray, poles: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, float]:
    """Nonlinear least squares of offset + damped sinusoids from initial poles.

    Variable projection (Golub & Pereyra, with Kaufman's Jacobian): for given rates and
    frequencies the offset and amplitudes are a linear least-squares solution, so only the
    2K rates and frequencies are iterated on. Same minimum as fitting all 4K + 1 parameters,
    in far fewer steps: a record with little more than noise took up to 1400 evaluations,
    and hit the evaluation limit, with all of them free.

    Returns the parameters (α₁, ω₁, …, c, a₁, b₁, …), their covariance (from the full
    problem's Jacobian, its columns scaled to unit norm, times the residual variance,
    widened by (1 + ρ)/(1 − ρ) when the residuals' lag-1 correlation ρ is significant) and
    the residual sum of squares (infinite where the model overflows).
    """
    count = len(poles)
    start = np.column_stack([-poles.real, poles.imag]).ravel()
    projection = _VariableProjection(tau, values)
    result = least_squares(projection.residual, start, jac=projection.jacobian, method="lm",
                           x_scale="jac")
    columns, linear, fitted_residual, basis = projection.at(result.x)
    parameters = np.concatenate([result.x, linear])
    if basis is None:   # the model overflows at the end point: no fit (the caller skips it)
        return parameters, np.full((len(parameters), len(parameters)), np.nan), np.inf
    rss = float(fitted_residual @ fitted_residual)
    dof = len(values) - len(parameters)
    variance = rss / dof
    correlation = float(np.corrcoef(fitted_residual[:-1], fitted_residual[1:])[0, 1])
    if correlation > 2.0 / np.sqrt(len(values)):
        variance *= (1 + correlation) / (1 - correlation)
    full_jacobian = np.hstack([_nonlinear_columns(tau, columns, linear, count), columns])
    # Columns scaled to unit norm before the inverse: a growing component's columns reach
    # e^30 at the window's end, and pinv's cut-off, relative to them, zeroed the variance of
    # every rate and frequency (σ 1e-26 Hz reported for a 2 Hz component known to ±0.1 Hz).
    with np.errstate(over="ignore", invalid="ignore"):
        scale = np.linalg.norm(full_jacobian, axis=0)
    if not np.isfinite(scale).all():   # a component grown beyond 1e154 spans one sample
        return parameters, np.full((len(parameters), len(parameters)), np.nan), np.inf
    scale[scale == 0] = 1.0
    scaled = full_jacobian / scale
    covariance = variance * np.linalg.pinv(scaled.T @ scaled) / np.outer(scale, scale)
    return parameters, covariance, rss


def fit_damped_sinusoids(time_s: ArrayLike, values: ArrayLike, max_components: int = 4,
                         start_s: float | None = None, end_s: float | None = None,
                         ) -> DampedSinusoidFit:
    """Offset + K damped sinusoids: matrix-pencil start, nonlinear least squares, K by BIC.

    For K = 1 … `max_components` the pencil of order 2K + 1 gives the initial poles
    (0 < f < 0.45 fs, not growing fast), least squares on the real samples and timestamps
    refines them, and the smallest BIC = N ln(RSS/N) + (4K + 1) ln N chooses K.
    """
    t, y = finite_window(time_s, values, start_s, end_s)
    _, uniform, step = uniform_record(t, y)
    tau = t - t[0]
    best: DampedSinusoidFit | None = None
    try:   # one SVD serves every K (its pencil L is theirs too, unless N < 30)
        vectors = pencil_vectors(uniform - uniform.mean(), 3)
    except DecayError:
        vectors = np.empty((0, 0))
    for count in range(1, max_components + 1):
        try:
            poles = pencil_poles(vectors, step, 2 * count + 1)
        except DecayError:
            break
        nyquist = np.pi / step
        keep = (poles.imag > 0) & (poles.imag < 0.9 * nyquist) & (poles.real < 0.1 * poles.imag)
        poles = poles[keep]
        if len(poles) == 0:
            continue
        parameters, covariance, rss = _fit_components(tau, y, poles)
        found = len(poles)
        rates, omegas = parameters[0:2 * found:2], parameters[1:2 * found:2]
        if np.any(omegas <= 0) or np.any(omegas >= nyquist) or not 0 < rss < np.inf \
                or not np.isfinite(parameters).all():
            continue
        linear = parameters[2 * found:]
        components = tuple(
            DampedSinusoid(float(rates[k]), float(omegas[k]), float(linear[1 + 2 * k]),
                           float(linear[2 + 2 * k]), covariance[2 * k:2 * k + 2, 2 * k:2 * k + 2])
            for k in range(found))
        bic = len(y) * np.log(rss / len(y)) + len(parameters) * np.log(len(y))
        if best is None or bic < best.bic:
            # Largest over the window, not at its start: a fast, heavily damped component
            # that fits one sample can start thousands of times larger than the mode (its
            # cos and sin terms cancelling) and be gone two samples later.
            best = DampedSinusoidFit(float(t[0]), float(t[-1]), float(linear[0]),
                                     tuple(sorted(components, key=lambda c: -c.norm(tau))),
                                     float(np.sqrt(rss / len(y))), tau, float(bic))
    if best is None:
        raise DecayError("no decaying oscillation found in the record")
    return best
