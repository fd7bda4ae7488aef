"""What a step or release response tells: settling time, overshoot and frequencies.

Used by ``simulate`` and by the damping fit; times in s, positions in m.
"""
import numpy as np

#: the settling band: this fraction of the move, and never under SETTLE_FLOOR (m)
SETTLE_FRACTION = 0.02
SETTLE_FLOOR = 1e-4
#: the record's last fraction: its median is the final value, and a response has settled only
#: if it stayed in the band over at least this stretch before the end (a shorter stay is a
#: swing passing through the band, not rest)
SETTLE_TAIL = 0.2


def final_value(path, tail=SETTLE_TAIL):
    """Return the path's (T, 3) final value (m): the median of its last ``tail``, per axis.

    The last sample of a run cut short sits anywhere on the swing; the median of the last
    fifth is the centre it swings about, and no outlier moves it.
    """
    path = np.asarray(path, dtype=float)
    count = max(1, int(round(tail * len(path))))
    return np.median(path[-count:], axis=0)


def settling_time(times, path, final=None):
    """Time (s) after which the path (T, 3) stays within the band around ``final``, or None.

    ``final`` defaults to :func:`final_value`; the band is 2 % of the move from the start, at
    least 0.1 mm. None (not settled within the run) unless the path stayed in the band over at
    least the last :data:`SETTLE_TAIL` of the record: a run that ends mid-swing has no
    settling time, however close its last sample is to itself.
    """
    times = np.asarray(times, dtype=float)
    path = np.asarray(path, dtype=float)
    final = final_value(path) if final is None else np.asarray(final, dtype=float)
    band = max(SETTLE_FRACTION * np.linalg.norm(final - path[0]), SETTLE_FLOOR)
    outside = np.nonzero(np.linalg.norm(path - final, axis=1) > band)[0]
    settled = times[0] if not len(outside) else (
        None if outside[-1] == len(path) - 1 else times[outside[-1] + 1])
    if settled is None or times[-1] - settled < SETTLE_TAIL * (times[-1] - times[0]):
        return None
    return float(settled)


def overshoot(path, final=None):
    """Overshoot (% of the move) beyond ``final`` along the move's direction (0 if none).

    ``final`` defaults to :func:`final_value`.
    """
    path = np.asarray(path, dtype=float)
    final = final_value(path) if final is None else np.asarray(final, dtype=float)
    move = final - path[0]
    size = np.linalg.norm(move)
    if size == 0.0:
        return 0.0
    beyond = (path - final) @ (move / size)
    return float(max(0.0, beyond.max()) / size * 100.0)


def spectrum_peaks(times, path, count=3, final=None):
    """Frequencies (Hz) of the ``count`` largest peaks of the motion's spectrum, low to high.

    The power spectra of the path's deviation from ``final`` (its end) along x, y and z,
    Hann-windowed and zero-padded 16 times, are summed; a peak is the largest value within
    1 / duration either side (the window's main lobe is 2 / duration wide: its side lobes and
    the decay's low-frequency skirt are no peaks) and at least 2 / duration above zero.
    """
    path = np.asarray(path, dtype=float)
    final = path[-1] if final is None else np.asarray(final, dtype=float)
    deviation = path - final
    if len(times) < 8:
        return []
    dt = float(np.median(np.diff(times)))
    size = 16 * len(times)
    window = np.hanning(len(times))
    power = np.zeros(size // 2 + 1)
    for axis in range(3):
        signal = deviation[:, axis] - deviation[:, axis].mean()
        power += np.abs(np.fft.rfft(signal * window, size)) ** 2
    freq = np.fft.rfftfreq(size, dt)
    duration = times[-1] - times[0]
    reach = 16  # bins in 1 / duration
    index = [i for i in range(1, len(power) - 1)
             if freq[i] >= 2.0 / duration
             and power[i] > power[i - 1]
             and power[i] == power[max(0, i - reach):i + reach + 1].max()]
    index = np.array(index, dtype=int)
    if not len(index):
        return []
    strongest = index[np.argsort(power[index])[::-1][:count]]
    return sorted(float(freq[i]) for i in strongest)
