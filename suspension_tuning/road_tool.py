"""``road``: what a road is, before the vehicle drives it.

Usage::

    road belgian_paving                       # a road of config/road.yaml
    road config/roads/belgian_block.crg       # an OpenCRG file
    road my_track.csv --plot out/psd.png      # a CSV file, with its PSD plot
    road belgian_paving --write out/sett.crg  # write a road's wheel tracks to a file
    road belgian_paving --compare belgian_block_measured   # 10 m windows side by side

For any named road or road file (without the fade-in a scenario starts on) it prints the
length and the RMS elevation of each wheel track (mean and linear trend removed), and
the ISO 8608 fit of each track: G_d(n0) at n0 = 0.1 cycles/m, the waviness w and the
class A-H, over a stated band (default
0.1-10 cycles/m, narrowed to what the road's length resolves; G_d(n0) extrapolated when
the band starts above n0).  ``--plot`` draws the Welch PSD of both tracks with the fitted
lines against the ISO 8608 class boundaries.  ``--write`` writes the wheel tracks as an
OpenCRG (``.crg``) or CSV (``.csv``) file that config/road.yaml can name.
``--compare OTHER`` cuts both roads' wheel tracks (without their fade-in) into windows
of ``--window-m`` (default 10 m, the measured Belgian block's length) and prints each
road's window statistics (:func:`suspension_tuning.vehicle.road_analysis.track_windows`):
RMS, RMS in the stone band 1-10 cycles/m, RMS of wavelengths below 1 m, mean PSD and PSD
slope in the stone band.  For an OpenCRG file it adds the long sections across the
road's width every 0.15 m (about one stone) that have no missing value.

The fit is :func:`suspension_tuning.vehicle.road_analysis.iso8608_fit`; the roads are
read as every scenario reads them (:func:`suspension_tuning.vehicle.road.resolve_road`).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

from suspension_tuning.paths import file_sha256
from suspension_tuning.vehicle import road as road_mod
from suspension_tuning.vehicle import road_analysis as ra
from suspension_tuning.vehicle.road_files import FileRoadSpec, write_crg, write_csv


def parse_args(argv: list[str]) -> argparse.Namespace:
    """Parse the command-line options of ``road``."""
    parser = argparse.ArgumentParser(prog='road', description=__doc__.split('\n')[0])
    parser.add_argument('road', help='a road of config/road.yaml, or a .crg or .csv file')
    parser.add_argument('--band', type=float, nargs=2, metavar=('LO', 'HI'),
                        default=list(ra.DEFAULT_BAND_CYC_PER_M),
                        help='band of the ISO 8608 fit, cycles/m (default 0.1 10)')
    parser.add_argument('--segment-m', type=float, default=ra.DEFAULT_SEGMENT_M,
                        help='Welch segment length, m (default 50; a shorter road is one '
                             'segment)')
    parser.add_argument('--track-m', type=float, default=None,
                        help='distance between the wheel tracks of a .crg file, m (default '
                             '1.486, the Defender 110)')
    parser.add_argument('--plot', type=Path, default=None, help='write the PSD plot here (PNG)')
    parser.add_argument('--speed-kmh', type=float, default=50.0,
                        help='speed of the temporal-frequency axis of the plot (default 50)')
    parser.add_argument('--write', type=Path, default=None,
                        help='write the wheel tracks to this .crg or .csv file')
    parser.add_argument('--compare', default=None, metavar='OTHER',
                        help='another road: window statistics of both side by side')
    parser.add_argument('--window-m', type=float, default=10.0,
                        help='window length of --compare, m (default 10)')
    return parser.parse_args(argv)


def describe(road: str, band: tuple[float, float], segment_m: float,
             track_m: float | None = None) -> dict:
    """Length, RMS and ISO 8608 fit of each track of a road (what ``road`` prints).

    Returns
    -------
    dict
        'spec', 'profile', 'length_m', 'dx_m', 'band' (the band fitted), 'segment_m',
        and per track ('left', 'right'): 'rms_m', 'fit' (Iso8608Fit), 'psd' (n, G_d).
    """
    spec = _without_fade(road_mod.resolve_road(road))  # the road, not the run's start
    if track_m is not None and isinstance(spec, FileRoadSpec):
        from dataclasses import replace

        spec = replace(spec, track_m=track_m)
    profile = road_mod.synthesise_tracks(spec)
    dx = float(profile.x_m[1] - profile.x_m[0])
    used = ra.usable_band(profile.length_m, band, dx, segment_m)
    out = {'spec': spec, 'profile': profile, 'length_m': profile.length_m, 'dx_m': dx,
           'band': used, 'segment_m': min(segment_m, profile.length_m)}
    for side, z in (('left', profile.z_left_m), ('right', profile.z_right_m)):
        n, g = ra.welch(z, dx, segment_m)
        out[side] = {'rms_m': ra.detrended_rms(z), 'fit': ra.iso8608_fit(n, g, used),
                     'psd': (n, g)}
    return out


def report(info: dict, band: tuple[float, float]) -> list[str]:
    """The lines ``road`` prints for :func:`describe`'s result."""
    spec = info['spec']
    if isinstance(spec, FileRoadSpec):
        source = f'file {spec.file} (sha256 {file_sha256(spec.file)[:16]})'
    else:
        source = f'{type(spec).__name__} (synthesised, seed {spec.seed})'
    lo, hi = info['band']
    lines = [f'road: {source}',
             f'length_m: {info["length_m"]:.3f}',
             f'sample_spacing_m: {info["dx_m"]:g}']
    for side in ('left', 'right'):
        lines.append(f'rms_{side}_mm: {1e3 * info[side]["rms_m"]:.2f}  (mean and linear trend '
                     'removed)')
    note = '' if (lo, hi) == tuple(band) else (f' (asked {band[0]:g}-{band[1]:g}; the '
                                                f'road resolves {lo:.3g}-{hi:.3g})')
    lines.append(f'iso8608_band_cyc_per_m: {lo:.3g}-{hi:.3g}{note}, third-octave bands of the '
                 f'Welch PSD ({info["segment_m"]:.3g} m segments)')
    for side in ('left', 'right'):
        fit = info[side]['fit']
        extra = ', extrapolated to n0' if fit.extrapolated else ''
        lines.append(f'iso8608_{side}: G_d(n0) = {fit.gd_n0_m3:.3g} m^3, w = {fit.waviness:.2f}, '
                     f'class {fit.iso_class} (n0 = 0.1 cycles/m{extra}; {fit.n_bands} bands)')
    return lines


def _without_fade(spec):
    from dataclasses import replace

    return replace(spec, ramp_in_m=0.0) if spec.ramp_in_m else spec


def compare(roads: list[str], window_m: float = 10.0) -> dict[str, dict[str, np.ndarray]]:
    """Window statistics of each road's two wheel tracks (and a CRG file's long sections).

    Returns
    -------
    dict
        Label -> :func:`~suspension_tuning.vehicle.road_analysis.track_windows` result;
        labels are the road texts and, for OpenCRG files, ``'<road>, long sections'``.
    """
    out = {}
    for road in roads:
        spec = _without_fade(road_mod.resolve_road(road))
        if isinstance(spec, FileRoadSpec):
            from dataclasses import replace

            spec = replace(spec, length_m=None, repeat=False)
        profile = road_mod.synthesise_tracks(spec)
        dx = float(profile.x_m[1] - profile.x_m[0])
        out[road] = ra.track_windows([profile.z_left_m, profile.z_right_m], dx, window_m)
        if isinstance(spec, FileRoadSpec) and spec.kind == 'crg':
            sections = crg_long_sections(spec.file, 0.15)
            out[f'{road}, long sections'] = ra.track_windows(sections, dx, window_m)
    return out


def crg_long_sections(path: str, spacing_m: float) -> list[np.ndarray]:
    """Long sections of an OpenCRG file every ``spacing_m`` across it, without missing values."""
    import pyopencrg

    raw = pyopencrg.read(path)
    v, z = np.asarray(raw.v), np.asarray(raw.z)
    step = max(1, int(round(spacing_m / float(np.median(np.diff(v))))))
    return [z[:, j] for j in range(0, v.size, step) if np.all(np.isfinite(z[:, j]))]


def compare_report(stats: dict[str, dict[str, np.ndarray]], window_m: float) -> list[str]:
    """Lines of ``road --compare``: per quantity, each road's median, 10-90 % and range."""
    lines = [f'window statistics, {window_m:g} m windows (trend removed), both wheel tracks '
             'pooled: median [10 %, 90 %] (min-max), n windows']
    for key, (text, unit, scale) in ra.WINDOW_QUANTITIES.items():
        lines.append(f'{key} ({text}, {unit}):')
        for label, values in stats.items():
            v = scale * values[key]
            p10, p50, p90 = np.percentile(v, [10, 50, 90])
            lines.append(f'  {label}: {p50:.3g} [{p10:.3g}, {p90:.3g}] ({v.min():.3g}-'
                         f'{v.max():.3g}), n {v.size}')
    return lines


def plot(info: dict, path: Path, speed_kmh: float, title: str) -> Path:
    """Write the PSD of both tracks with the fitted lines against the ISO 8608 classes."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5.5))
    n_max = 0.5 / info['dx_m']
    nn = np.logspace(-2, np.log10(n_max), 200)
    lower = np.concatenate(([ra.ISO8608_CLASS_UPPER_M3[0] / 4], ra.ISO8608_CLASS_UPPER_M3))
    for k, lim in enumerate(lower):
        ax.loglog(nn, lim * (nn / ra.N0_CYC_PER_M) ** -2, color='0.75', lw=0.8)
        name = 'A lower' if k == 0 else f'{ra.ISO8608_CLASSES[k - 1]}/{ra.ISO8608_CLASSES[k]}'
        n_text = 0.7 * n_max
        ax.text(n_text, lim * (n_text / ra.N0_CYC_PER_M) ** -2 * 1.2, name, color='0.45',
                fontsize=7, ha='right')
    lo, hi = info['band']
    nb = np.logspace(np.log10(lo), np.log10(hi), 50)
    for side, colour in (('left', 'C0'), ('right', 'C1')):
        n, g = info[side]['psd']
        fit = info[side]['fit']
        ax.loglog(n, g, color=colour, lw=0.9, alpha=0.8, label=f'{side} track (Welch)')
        ax.loglog(nb, fit.gd(nb), color=colour, lw=2.0, ls='--',
                  label=f'{side} fit: G_d(n0) {fit.gd_n0_m3:.2g} m^3, w {fit.waviness:.2f}, '
                        f'class {fit.iso_class}')
    ax.axvspan(lo, hi, color='0.5', alpha=0.06, lw=0)
    ax.set_xlim(0.01, n_max)
    ax.set_ylim(1e-11, 1e-1)
    ax.set_xlabel('spatial frequency n [cycles/m]')
    ax.set_ylabel('displacement PSD G_d(n) [m^3]')
    ax.grid(True, which='major', alpha=0.3)
    top = ax.secondary_xaxis('top', functions=(lambda x: x * speed_kmh / 3.6,
                                               lambda f: f * 3.6 / speed_kmh))
    top.set_xlabel(f'temporal frequency at {speed_kmh:g} km/h [Hz]')
    ax.legend(fontsize=7, loc='lower left')
    ax.set_title(f'{title}: ISO 8608 fit over {lo:.2g}-{hi:.2g} cycles/m (shaded) against the '
                 'class boundaries (grey, w = 2)', fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``road``."""
    args = parse_args(sys.argv[1:] if argv is None else argv)
    band = (float(args.band[0]), float(args.band[1]))
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter('always')
            info = describe(args.road, band, args.segment_m, args.track_m)
        for warning in caught:
            print(f'warning: {warning.message}', file=sys.stderr)
        for line in report(info, band):
            print(line)
        if args.plot is not None:
            print(f'plot: {plot(info, args.plot, args.speed_kmh, Path(args.road).name)}')
        if args.compare is not None:
            for line in compare_report(compare([args.road, args.compare], args.window_m),
                                       args.window_m):
                print(line)
        if args.write is not None:
            suffix = args.write.suffix.lower()
            comment = f'wheel tracks of {args.road}, written by the road command'
            spec = info['spec']
            track = spec.track_m if hasattr(spec, 'track_m') else 1.486
            if suffix == '.crg':
                write_crg(info['profile'], args.write, track, comment=comment)
            elif suffix == '.csv':
                write_csv(info['profile'], args.write, comment=comment)
            else:
                raise ValueError(f'--write needs a .crg or .csv file name, got {args.write}')
            print(f'written: {args.write}')
    except ValueError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    return 0


if __name__ == '__main__':
    sys.exit(main())
