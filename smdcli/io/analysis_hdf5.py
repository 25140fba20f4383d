"""The files of the analyses of a record or a scene: response and inelastic spectra, shock response spectra,
response-spectrum analyses. Every axis a named dimension scale (smdcli.io.hdf5.axis), every write atomic.

Must not import: commands, cli.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from smdcli.io.atomic import atomic_path
from smdcli.io.hdf5 import axis, with_scales, write_provenance


def write_spectrum(path: Path, record, spectrum, inelastic=None) -> None:
    """A response spectrum file: period (P) and damping (Z) scales, Sd, Sv, Sa (Z, P), the record it came from,
    and the inelastic spectra under /inelastic (K, Z, P) where asked for."""
    import h5py

    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        write_provenance(f, "spectrum")
        f.attrs["title"] = f"Response spectrum of {Path(record.path).name}"
        f.attrs["record_path"] = record.path
        f.attrs["method"] = ("exact: the closed-form response to the record linear between samples; each peak "
                             "located between samples as a root of the closed-form velocity")
        period = f.create_dataset("period", data=spectrum.period)
        period.make_scale("period")
        period.attrs["units"] = "s"
        damping = f.create_dataset("damping", data=spectrum.damping)
        damping.make_scale("damping")
        damping.attrs["units"] = "1"
        for name, data, units, meaning in (
                ("Sd", spectrum.Sd, "m", "peak relative displacement"),
                ("Sv", spectrum.Sv, "m/s", "pseudo-spectral velocity, (2 pi / T) Sd"),
                ("Sa", spectrum.Sa, "m/s^2", "pseudo-spectral acceleration, (2 pi / T)^2 Sd")):
            ds = with_scales(f.create_dataset(name, data=data), damping, period)
            ds.attrs["units"] = units
            ds.attrs["description"] = meaning
        if inelastic is not None:
            _write_inelastic(f.create_group("inelastic"), inelastic)
        _write_record(f, record)


def _write_inelastic(group, x) -> None:
    """/inelastic: Cy, Ry, ductility_demand, peak and residual deformation on (ductility|strength, damping, period)."""
    from smdcli.analysis.inelastic import TOLERANCE

    group.attrs["kind"] = f"constant {x.kind}"
    group.attrs["law"] = "bilinear" if x.hardening else "elastoplastic"
    group.attrs["hardening"] = x.hardening
    group.attrs["method"] = ("each oscillator solved exactly event to event (yield, unloading); constant ductility: "
                             "the largest strength giving the target, found by scanning down from the elastic "
                             f"strength and false position to a relative {TOLERANCE:g} of the ductility")
    target = axis(group, x.kind, x.targets)
    target.attrs["units"] = "1"
    target.attrs["description"] = ("target ductility factor" if x.kind == "ductility"
                                   else "yield strength coefficient Cy = fy / (m g)")
    damping = axis(group, "damping", x.damping)
    damping.attrs["units"] = "1"
    period = axis(group, "period", x.period)
    period.attrs["units"] = "s"
    for name, data, units, meaning in (
            ("Cy", x.Cy, "1", "yield strength coefficient fy / (m g)"),
            ("Ry", x.Ry, "1", "strength reduction factor f0 / fy (f0: the elastic peak force)"),
            ("ductility_demand", x.ductility, "1", "peak deformation over yield deformation"),
            ("peak_deformation", x.peak_deformation, "m", "largest |u| relative to the ground"),
            ("residual_deformation", x.residual_deformation, "m", "plastic deformation at the record's end"),
            ("found", x.found.astype(np.int8), "1", "1 where a strength gives the target (constant ductility)")):
        ds = with_scales(group.create_dataset(name, data=data), target, damping, period)
        ds.attrs["units"] = units
        ds.attrs["description"] = meaning


def write_shock_spectrum(path: Path, record, srs) -> None:
    """A shock response spectrum file: q and frequency scales, positive, negative, maximax (Q, F) in g and the
    times of the extremes, the record it came from."""
    import h5py

    from smdcli.scenario.spec import STANDARD_GRAVITY

    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        write_provenance(f, "spectrum")
        f.attrs["title"] = f"Shock response spectrum of {Path(record.path).name}"
        f.attrs["record_path"] = record.path
        f.attrs["kind"] = "srs"
        f.attrs["method"] = ("exact for the record linear between samples; every extreme of the absolute acceleration "
                             "located between samples, over the record and 1.25 periods of residual free motion")
        q = axis(f, "q", srs.q)
        q.attrs["units"] = "1"
        q.attrs["description"] = "quality factor Q = 1 / (2 zeta)"
        frequency = axis(f, "frequency", srs.frequency)
        frequency.attrs["units"] = "Hz"
        for name, data, units, meaning in (
                ("positive", srs.positive / STANDARD_GRAVITY, "g", "largest absolute acceleration of the mass"),
                ("negative", srs.negative / STANDARD_GRAVITY, "g", "most negative absolute acceleration of the mass"),
                ("maximax", srs.maximax / STANDARD_GRAVITY, "g", "largest magnitude of either sign"),
                ("positive_time", srs.positive_time, "s", "when the positive extreme occurs"),
                ("negative_time", srs.negative_time, "s", "when the negative extreme occurs")):
            ds = with_scales(f.create_dataset(name, data=data), q, frequency)
            ds.attrs["units"] = units
            ds.attrs["description"] = meaning
        _write_record(f, record)


def write_rsa(path: Path, run) -> None:
    """A response-spectrum analysis file: /modes per mode, /modal peaks per mode, /combined/<rule> peaks."""
    import h5py

    from smdcli.analysis.rsa import COMBINATIONS

    a, m = run.analysis, run.analysis.modes
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        write_provenance(f, "rsa")
        f.attrs["title"] = f"Response-spectrum analysis of {Path(run.scenario).name}"
        f.attrs["scenario_path"] = run.scenario
        f.attrs["spectrum_path"] = run.source.path
        f.attrs["spectrum_kind"] = run.source.kind
        f.attrs["combination"] = run.combination
        f.attrs["modes_used"] = a.used
        f.attrs["total_mass"] = m.total_mass
        f.attrs["influence"] = "ones: every DOF moves with the ground"
        modes = f.create_group("modes")
        mode = axis(modes, "mode", np.arange(1, len(m.period) + 1))
        dof = axis(modes, "dof", list(run.dofs))
        for name, data, units in (("period", m.period, "s"), ("omega", m.omega, "rad/s"), ("damping", m.damping, "1"),
                                  ("participation", m.participation, "kg^0.5"),
                                  ("effective_mass", m.effective_mass, "kg"), ("cumulative_ratio", m.cumulative_ratio, "1")):
            with_scales(modes.create_dataset(name, data=data), mode).attrs["units"] = units
        shapes = with_scales(modes.create_dataset("shapes", data=m.shapes), dof, mode)
        shapes.attrs["units"] = "kg^-0.5"
        shapes.attrs["description"] = "mass-normalised mode shapes, one column per mode"
        modal = f.create_group("modal")
        used = axis(modal, "mode", np.arange(1, a.used + 1))
        modal_dof = axis(modal, "dof", list(run.dofs))
        element = axis(modal, "element", list(run.elements)) if run.elements else None
        with_scales(modal.create_dataset("Sa", data=a.Sa), used).attrs["units"] = "m/s^2"
        with_scales(modal.create_dataset("displacement", data=a.displacement), used, modal_dof).attrs["units"] = "m"
        if element is not None:
            with_scales(modal.create_dataset("deformation", data=a.deformation), used, element).attrs["units"] = "m"
            with_scales(modal.create_dataset("force", data=a.force), used, element).attrs["units"] = "N"
        with_scales(modal.create_dataset("base_shear", data=a.base_shear), used).attrs["units"] = "N"
        for rule in COMBINATIONS:
            c = a.combined(rule)
            group = f.create_group(f"combined/{rule}")
            group_dof = axis(group, "dof", list(run.dofs))
            with_scales(group.create_dataset("displacement", data=c["displacement"]), group_dof).attrs["units"] = "m"
            if run.elements:
                group_element = axis(group, "element", list(run.elements))
                with_scales(group.create_dataset("deformation", data=c["deformation"]), group_element).attrs["units"] = "m"
                with_scales(group.create_dataset("force", data=c["force"]), group_element).attrs["units"] = "N"
            group.create_dataset("base_shear", data=c["base_shear"]).attrs["units"] = "N"


def _write_record(f, record) -> None:
    """The /record group: the acceleration as used (m/s^2) on its time scale, and the file it came from."""
    group = f.create_group("record")
    time = group.create_dataset("time", data=record.time)
    time.make_scale("time")
    time.attrs["units"] = "s"
    acc = with_scales(group.create_dataset("acceleration", data=record.acceleration), time)
    acc.attrs["units"] = "m/s^2"
    _record_source(group, record)


def write_record(path: Path, record, processed) -> None:
    """A processed record: time scale, raw and processed acceleration, velocity, displacement, running Arias
    intensity and the Husid curve; the measures as root attributes."""
    import h5py

    m = processed.measures
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        write_provenance(f, "record")
        f.attrs["title"] = f"Record {Path(record.path).name}, processed"
        f.attrs["record_path"] = record.path
        f.attrs["baseline"] = processed.baseline
        f.attrs["filter_hz"] = np.array(processed.band if processed.band else [np.nan, np.nan])
        f.attrs["filter_order"] = processed.order if processed.band else 0
        for name, value, units in (("pga", m.pga, "m/s^2"), ("pgv", m.pgv, "m/s"), ("pgd", m.pgd, "m"),
                                   ("arias_intensity", m.arias, "m/s"), ("d5_95", m.d5_95, "s"),
                                   ("d5_75", m.d5_75, "s"), ("t5", m.t5, "s"), ("t75", m.t75, "s"),
                                   ("t95", m.t95, "s"), ("cav", m.cav, "m/s"), ("housner_si", m.housner, "m")):
            f.attrs[name] = value
            f.attrs[f"{name}_units"] = units
        time = f.create_dataset("time", data=processed.time)
        time.make_scale("time")
        time.attrs["units"] = "s"
        husid = processed.arias / processed.arias[-1] if processed.arias[-1] > 0 else processed.arias * 0
        for name, data, units, meaning in (
                ("raw_acceleration", processed.raw, "m/s^2", "as read (units, scale and shift applied)"),
                ("acceleration", processed.acceleration, "m/s^2", "baseline-corrected, then filtered"),
                ("velocity", processed.velocity, "m/s", "exact integral of the straight lines, from rest"),
                ("displacement", processed.displacement, "m", "exact integral of the velocity, from rest"),
                ("arias", processed.arias, "m/s", "running Arias intensity pi/(2g) integral of a^2"),
                ("husid", husid, "1", "running Arias intensity over its total")):
            ds = with_scales(f.create_dataset(name, data=data), time)
            ds.attrs["units"] = units
            ds.attrs["description"] = meaning
        _record_source(f.create_group("source"), record)


def _record_source(group, record) -> None:
    """What a record file was: its text, hash, how it was read (format, a COSMOS channel), its sampling and unit."""
    group.attrs["units_in_file"] = record.units
    group.attrs["format"] = record.format
    if record.channel is not None:
        group.attrs["channel"] = record.channel
    group.attrs["step_s"] = record.step
    group.attrs["file_text"] = record.text
    group.attrs["sha256"] = hashlib.sha256(record.text.encode()).hexdigest()


def write_psd(path: Path, run) -> None:
    """A random-vibration file: /frequency, /input_psd, /response/<quantity> PSDs (frequency, name) and
    /rms/<quantity> (name), the method and input as attributes."""
    import h5py

    from smdcli.scenario.spec import STANDARD_GRAVITY

    units = {"displacement": "m", "velocity": "m/s", "acceleration": "m/s^2", "spring_force": "N",
             "damper_force": "N"}
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        write_provenance(f, "psd")
        f.attrs["title"] = f"Random vibration of {Path(run.scenario).name}"
        f.attrs["scenario_path"] = run.scenario
        f.attrs["input"] = "support acceleration" if run.support else f"force on {run.on}"
        f.attrs["method"] = run.method
        f.attrs["white_noise_level"] = run.white if run.white is not None else np.nan
        frequency = axis(f, "frequency", run.frequency)
        frequency.attrs["units"] = "Hz"
        psd_units = "(m/s^2)^2/Hz" if run.support else "N^2/Hz"
        ds = with_scales(f.create_dataset("input_psd", data=run.input_psd), frequency)
        ds.attrs["units"] = psd_units
        if run.profile is not None:
            group = f.create_group("profile")
            breakpoint_axis = axis(group, "breakpoint_hz", run.profile.frequency)
            breakpoint_axis.attrs["units"] = "Hz"
            with_scales(group.create_dataset("level", data=run.profile.level), breakpoint_axis).attrs["units"] = psd_units
        groups = np.array(run.groups)
        names = np.array(run.names)
        for quantity in dict.fromkeys(run.groups):
            pick = groups == quantity
            response = f.require_group("response")
            rms = f.require_group("rms")
            name_axis = axis(response, f"{quantity}_name", list(names[pick]))
            ds = with_scales(response.create_dataset(quantity, data=run.response_psd[:, pick]), frequency, name_axis)
            ds.attrs["units"] = f"({units[quantity]})^2/Hz"
            rms_axis = axis(rms, f"{quantity}_name", list(names[pick]))
            ds = with_scales(rms.create_dataset(quantity, data=run.rms[pick]), rms_axis)
            ds.attrs["units"] = units[quantity]
            if quantity == "acceleration" and run.support:
                ds.attrs["description"] = "absolute acceleration (relative plus the support's)"
                g = with_scales(rms.create_dataset("acceleration_g", data=run.rms[pick] / STANDARD_GRAVITY),
                                rms_axis)
                g.attrs["units"] = "g"
        modes = f.create_group("modes")
        mode = axis(modes, "mode", np.arange(1, len(run.natural_hz) + 1))
        with_scales(modes.create_dataset("natural_frequency", data=run.natural_hz), mode).attrs["units"] = "Hz"
        with_scales(modes.create_dataset("damping", data=run.damping), mode).attrs["units"] = "1"
