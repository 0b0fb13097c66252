"""A user's full vehicle model as a Functional Mock-up Unit (FMI 2.0 / 3.0 co-simulation).

:class:`FmuModel` opens an FMU with FMPy and a mapping file (docs/fmu.md) and checks
them together at construction: the file opens, it is a co-simulation FMU of FMI 2.0 or
3.0 with a binary for this platform, and every mapped name exists with a fitting
causality (parameter / input / output), a real type and, where the FMU declares one,
a unit of the right dimension.  Every problem found is one line of the
:class:`FmuConfigError`, naming the variable.

:meth:`FmuModel.evaluate` runs a batch of designs, each on a fresh instance of the
FMU: the design's physical settings (eq. 4 inverse, section 5.1) go to the mapped
parameters, the road under each wheel (ride, when the FMU takes it) comes from the
road model at the mapped speed and wheelbase, and the sampled outputs are scored by
the same code as the built-in model
(:func:`suspension_tuning.vehicle.scenarios.ride_objective`, BS 6841 W_b weighting
applied here; :func:`~suspension_tuning.vehicle.scenarios.handling_objective`).  It
returns what :func:`suspension_tuning.evaluation.evaluate` returns.  A design whose
run fails, stops early or gives a non-finite output raises :class:`FmuRunError`
naming the design, the simulation time reached and the FMU's own last messages (its FMI
logger callback, :class:`~suspension_tuning.fmu.fmi_log.FmuMessage`; each message also
goes to ``on_message``).
:mod:`suspension_tuning.fmu.isolated` runs the same designs in child processes that
can be stopped.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import tempfile
import time
import zipfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

import numpy as np
import yaml

from suspension_tuning.evaluation import DesignEvaluation, metric_table
from suspension_tuning.fmu.fmi_log import FmuLog, FmuMessage
from suspension_tuning.fmu.mapping import CORNERS, FmuMapping, ScenarioMapping, load_mapping
from suspension_tuning.fmu.units import UNITS, Conversion, resolve
from suspension_tuning.model_identity import with_fingerprint
from suspension_tuning.paths import file_sha256
from suspension_tuning.vehicle import design as design_mod
from suspension_tuning.vehicle import road as road_mod
from suspension_tuning.vehicle import scenarios as scen
from suspension_tuning.vehicle.full_model import RoadInput
from suspension_tuning.vehicle.params import load_scenarios_config, load_vehicle_params

FMI_VERSIONS = ('2.0', '3.0')
REAL_TYPES = ('Real', 'Float64', 'Float32')
#: Causalities a mapped variable may have, by its role.
PARAMETER_CAUSALITIES = ('parameter',)
INPUT_CAUSALITIES = ('input',)
OUTPUT_CAUSALITIES = ('output',)
#: fmi2Fatal / fmi3Fatal: the instance may not be called again.
FMI_FATAL = 4
#: Standard gravity, m/s^2 (static tyre load as a mass).
GRAVITY_MPS2 = 9.80665
#: Seat W_b RMS a road vehicle plausibly shows on a test road, m/s^2.  ISO 2631-1
#: Annex C calls < 0.315 m/s^2 "not uncomfortable" and > 2 "extremely uncomfortable";
#: the paper's Defender spans 0.7-4.4 at its corners on the Belgian paving.  The range is
#: wide on purpose: it catches factors of 10-1000 (a wrong unit), not a harsh vehicle.
PLAUSIBLE_SEAT_RMS_MPS2 = (0.05, 10.0)
#: Static tyre load against the mapped vehicle mass: a 15 % departure is no rounding
#: of the mass, nor the sprung/unsprung split; a wrong force unit is a factor 1000.
STATIC_LOAD_TOLERANCE = 0.15
#: A design range this many times away from the FMU's own start value of the parameter
#: is taken as a wrong unit (the paper's ranges span a factor 6 (volume) and 30 (dpsf):
#: a realistic start value lies inside or near them; a unit slip is 1000).
START_VALUE_FACTOR = 10.0
#: FMU libraries of closed models, kept loaded (FmuModel.close), and instances left after a
#: fatal status (with the logger callbacks they may still call).
_LOADED_LIBRARIES: list = []


class FmuConfigError(ValueError):
    """An FMU or mapping that cannot serve (one line per problem, each naming it)."""


class FmuRunError(RuntimeError):
    """A design whose FMU run failed, stopped early, or gave NaN or infinite outputs."""


def design_label(index: int, x: np.ndarray) -> str:
    """``design 1 (x = [0.9, 0.4])``: how errors name a design."""
    return f'design {index} (x = {np.round(np.asarray(x, float), 6).tolist()})'


def _require_fmpy():
    try:
        import fmpy
    except ImportError:  # pragma: no cover - fmpy is in requirements.txt
        raise FmuConfigError('the FMU worker needs FMPy (pip install fmpy)') from None
    return fmpy


class FmuModel:
    """A checked FMU with its mapping, evaluating designs like the built-in model.

    Each design runs in this process; ``on_message`` (None or a callable) receives the
    FMU's log messages (:class:`~suspension_tuning.fmu.fmi_log.FmuMessage`) as they come.

    Parameters
    ----------
    fmu_path : str or Path
        The .fmu file.
    mapping : FmuMapping, str or Path
        The mapping (see docs/fmu.md), or the path of its YAML file.

    Raises
    ------
    FmuConfigError
        The file is not a readable FMU, not co-simulation, of an unsupported FMI version
        or without a binary for this platform, or a mapped name does not fit it (each
        problem on its own line, naming the variable).
    MappingError
        The mapping file itself is bad.
    """

    on_message: Callable[[FmuMessage], None] | None = None

    def __init__(self, fmu_path: str | Path, mapping: FmuMapping | str | Path) -> None:
        fmpy = _require_fmpy()
        from fmpy.model_description import read_model_description

        self.path = Path(fmu_path)
        self.mapping = mapping if isinstance(mapping, FmuMapping) else load_mapping(mapping)
        #: The design space that turns normalised designs into the FMU's parameters.
        self.space = self.mapping.space or design_mod.load_design_space()
        keyed: dict[str, Any] = {var.key(axle): var for axle in design_mod.AXLES
                                 for var in (self.space.damper, self.space.spring)}
        keyed.update({v.name: v for v in self.space.catalogue if v.name not in keyed})
        if not self.path.is_file():
            raise FmuConfigError(f'fmu_path {self.path}: no such file')
        try:
            with zipfile.ZipFile(self.path) as archive:
                version = ElementTree.fromstring(
                    archive.read('modelDescription.xml')).get('fmiVersion')
            if version not in FMI_VERSIONS:
                raise FmuConfigError(f'{self.path.name}: FMI {version} is not supported '
                                     f'(FMI {" or ".join(FMI_VERSIONS)} co-simulation)')
            md = read_model_description(str(self.path), validate=False)
        except FmuConfigError:
            raise
        except Exception as error:  # noqa: BLE001 - any reader failure: not an FMU
            raise FmuConfigError(f'{self.path.name}: not a readable FMU ({error})') from None
        self.model_description = md
        if md.coSimulation is None:
            raise FmuConfigError(f'{self.path.name}: not a co-simulation FMU (it offers '
                                 'model exchange only; export it for co-simulation)')
        platform = fmpy.platform if md.fmiVersion == '2.0' else fmpy.platform_tuple
        binary = (f'binaries/{platform}/{md.coSimulation.modelIdentifier}'
                  f'{fmpy.sharedLibraryExtension}')
        with zipfile.ZipFile(self.path) as archive:
            names = archive.namelist()
        if binary not in names:
            folders = sorted({n.split('/')[1] for n in names
                              if n.startswith('binaries/') and n.count('/') >= 2})
            raise FmuConfigError(f'{self.path.name}: no binary for this platform ({platform}: '
                                 f'{binary}); it has {folders or "no binaries"}')
        self.variables = {v.name: v for v in md.modelVariables}
        units = {u.name: u for u in (md.unitDefinitions or [])}
        problems: list[str] = []
        #: Start-up notes for the worker's log (inputs shared by several wheels...).
        self.notes: list[str] = []
        #: Mapped variables whose unit the FMU does not declare (the mapping's or SI is
        #: assumed): what the start-up plausibility check is for.
        self.undeclared_units: list[str] = []
        self.conversions: dict[str, dict[str, Conversion]] = {}
        for name, sm in self.mapping.scenarios.items():
            conv: dict[str, Conversion] = {}
            for key, ref in sm.design.items():
                conv[f'design.{key}'] = (
                    self._check(ref, PARAMETER_CAUSALITIES, units, problems)
                    if ref.scale is None else self._check_linear(ref, keyed[key], units,
                                                                 problems))
            if sm.speed_parameter is not None:
                conv['speed_parameter'] = self._check(sm.speed_parameter, PARAMETER_CAUSALITIES,
                                                      units, problems)
            for key, ref in sm.outputs.items():
                conv[f'outputs.{key}'] = self._check(ref, OUTPUT_CAUSALITIES, units, problems)
            if sm.road is not None:
                for _name, (ref, corners) in sm.road.variables().items():
                    checked = self._check(ref, INPUT_CAUSALITIES, units, problems)
                    conv.update({f'road.{c}': checked for c in corners})
                    if len(corners) > 1:
                        self.notes.append(
                            f'scenarios.{name}.road: FMU input {ref.name!r} gets the mean of '
                            f'the {"/".join(c.upper() for c in corners)} tracks')
            for pname in sm.parameters:
                self._check_fixed(sm, pname, problems)
            self.conversions[name] = conv
        if problems:
            raise FmuConfigError(f'{self.path.name} does not fit the mapping '
                                 f'{self.mapping.path or ""}:\n  ' + '\n  '.join(problems))
        self.roads = {name: self._road(sm) for name, sm in self.mapping.scenarios.items()
                      if sm.road is not None}
        self._track = None
        if 'handling' in self.mapping.scenarios and self.mapping.scenarios['handling'].windows \
                is None:
            self._track = scen.handling_setup(load_vehicle_params(),
                                              load_scenarios_config()['handling'])[0]
        self.sha256 = file_sha256(self.path)
        self._unzipdir = tempfile.mkdtemp(prefix='fmu_')
        try:
            fmpy.extract(str(self.path), unzipdir=self._unzipdir)
            # Held for the model's life: the shared library loads once (and is checked to
            # load now); each design's instance below takes and drops its own reference.
            self._library = self._slave('check')
        except Exception as error:
            shutil.rmtree(self._unzipdir, ignore_errors=True)
            raise FmuConfigError(f'{self.path.name}: its binary does not load ({error})') \
                from None

    # ------------------------------------------------------------------ checks
    def _variable(self, ref, causalities, problems) -> tuple[Any, list[str], str | None]:
        """The FMU variable ``ref`` names, its causality and type problems, its unit.

        A missing variable is a problem of its own (listed in ``problems``): None.
        """
        v = self.variables.get(ref.name)
        if v is None:
            problems.append(f'{ref.where}: the FMU has no variable {ref.name!r}')
            return None, [], None
        bad = []
        if v.causality not in causalities:
            bad.append(f'causality {v.causality!r}, expected {" or ".join(causalities)}')
        if v.type not in REAL_TYPES:
            bad.append(f'type {v.type}, expected a real ({", ".join(REAL_TYPES)})')
        declared = v.unit or (v.declaredType.unit if v.declaredType is not None else None)
        return v, bad, declared

    def _check(self, ref, causalities, units, problems) -> Conversion:
        v, bad, declared = self._variable(ref, causalities, problems)
        if v is None:
            return Conversion('')
        if not declared and ref.quantity != 'dimensionless':
            self.undeclared_units.append(f'{ref.where} ({ref.name}, taken as '
                                         f'{ref.unit or "SI"})')
        try:
            conversion = resolve(ref.quantity, declared, ref.unit, units)
        except ValueError as error:
            bad.append(str(error))
            conversion = Conversion('')
        if bad:
            problems.append(f'{ref.where}: FMU variable {ref.name!r} has ' + '; '.join(bad))
        return conversion

    def _check_linear(self, ref, var: design_mod.DesignVariable, units,
                      problems: list[str]) -> Conversion:
        """A linearly mapped design parameter: FMU value = offset + scale * v, in ref.unit.

        v is the design variable in its unit of the design space.  When the FMU declares
        the parameter's unit, the mapping's unit must be it, or one of the same dimension
        this tool converts (else the problem is listed).  Returned as the affine
        :class:`Conversion` from the variable's SI value to the FMU's value.
        """
        v, bad, declared = self._variable(ref, PARAMETER_CAUSALITIES, problems)
        if v is None:
            return Conversion('')
        to_declared = 1.0  # FMU value per value in the mapping's unit
        shift = 0.0
        if declared and declared != ref.unit:
            if ref.quantity:
                try:
                    fmu_unit = resolve(ref.quantity, declared, None, units)
                    to_declared = UNITS[ref.unit][1] / fmu_unit.factor
                    shift = -fmu_unit.offset / fmu_unit.factor
                except ValueError as error:
                    bad.append(str(error))
            else:
                bad.append(f'the mapping gives {ref.unit!r} but the FMU declares {declared!r}')
        elif not declared and ref.quantity not in ('', 'dimensionless'):
            self.undeclared_units.append(f'{ref.where} ({ref.name}, taken as {ref.unit})')
        if bad:
            problems.append(f'{ref.where}: FMU variable {ref.name!r} has ' + '; '.join(bad))
            return Conversion('')
        # FMU value = to_declared * (offset + scale * v_si / var.factor) + shift = A v + B
        a = to_declared * ref.scale / var.factor
        b = to_declared * ref.offset + shift
        return Conversion(ref.unit or '', 1.0 / a, -b / a)

    def _check_fixed(self, sm: ScenarioMapping, name: str, problems: list[str]) -> None:
        v = self.variables.get(name)
        where = f'scenarios.{sm.name}.parameters.{name}'
        if v is None:
            problems.append(f'{where}: the FMU has no variable {name!r}')
        elif v.causality not in (*PARAMETER_CAUSALITIES, *INPUT_CAUSALITIES):
            problems.append(f'{where}: FMU variable {name!r} has causality {v.causality!r}, '
                            'expected parameter or input')
        elif v.type == 'String' or v.type == 'Binary' or v.type == 'Clock':
            problems.append(f'{where}: FMU variable {name!r} has type {v.type}, expected a '
                            'number or a Boolean')

    def _road(self, sm: ScenarioMapping) -> RoadInput:
        ri = sm.road
        where = f'scenarios.{sm.name}.road'
        try:
            spec = (road_mod.load_road_spec(ri.road) if ri.road is not None
                    else scen.ride_road_spec(load_scenarios_config()['ride']))
        except ValueError as error:
            raise FmuConfigError(f'{where}.road: {error}') from None
        profile = road_mod.synthesise_tracks(spec)
        x_end = (ri.start_rear_axle_at_m + ri.wheelbase_m
                 + sm.speed_kmh / 3.6 * (sm.stop_time_s - sm.start_time_s))
        if x_end > profile.length_m:
            raise FmuConfigError(f'{where}: the front wheels reach {x_end:.1f} m, beyond the '
                                 f'end of the road ({profile.length_m:.1f} m)')
        return RoadInput.from_profile(profile, ri.contact_length_m)

    # ------------------------------------------------------------------ description
    def description(self) -> dict[str, Any]:
        """What a run's configuration records about this model (file, identity, mapping).

        With its fingerprint (:mod:`suspension_tuning.model_identity`): the FMU file's
        hash, the mapping's content and the worker's configuration files.
        """
        md = self.model_description
        token = 'guid' if md.fmiVersion == '2.0' else 'instantiation_token'
        return with_fingerprint({
            'model': 'fmu',
            'fmu_file': self.path.name,
            'fmu_path': str(self.path.resolve()),
            'fmu_sha256': self.sha256,
            'fmi_version': md.fmiVersion,
            token: md.guid,  # FMPy reads FMI 3.0's instantiationToken into guid
            'model_name': md.modelName,
            'generation_tool': md.generationTool,
            'fmu_mapping': str(self.mapping.path.resolve()) if self.mapping.path else '',
            'mapping': self.mapping.text,
            # The mapping's content (its comments and layout aside): part of the identity.
            'mapping_content': json.dumps(yaml.safe_load(self.mapping.text or '{}'),
                                          sort_keys=True, default=str),
            'integrator': None,  # the FMU's own solver: part of its file
        })

    def scenarios(self) -> tuple[str, ...]:
        """The scenarios the mapping serves."""
        return tuple(self.mapping.scenarios)

    def _start_value_warnings(self) -> list[str]:
        """Design parameters whose range, in the units assumed, is far from the FMU's start.

        An FMU's start value of a parameter is a value of its own vehicle in its own
        units.  When the design's range, converted to the unit the mapping states (the
        FMU declares none), lies more than ``START_VALUE_FACTOR`` away from it, the unit
        is most likely wrong (0.1-0.6 sent as litres to a parameter that starts at 300
        cm^3).
        """
        ranges = {var.key(axle): (var.axle(axle).low, var.axle(axle).high)
                  for axle in design_mod.AXLES for var in (self.space.damper, self.space.spring)}
        ranges.update({v.name: (v.low, v.high) for v in self.space.catalogue
                       if v.name not in ranges})
        out, seen = [], set()
        for name, sm in self.mapping.scenarios.items():
            for key, ref in sm.design.items():
                v = self.variables.get(ref.name)
                declared = v.unit or (v.declaredType.unit if v.declaredType is not None
                                      else None)
                if declared or ref.name in seen or v.start in (None, ''):
                    continue
                seen.add(ref.name)
                try:
                    start = abs(float(v.start))
                except ValueError:
                    continue
                conv = self.conversions[name][f'design.{key}']
                low, high = sorted(abs(float(conv.to_fmu(b))) for b in ranges[key])
                if start > 0 and (start > START_VALUE_FACTOR * high
                                  or start < low / START_VALUE_FACTOR):
                    factor = max(start / high, low / start)
                    out.append(f'{ref.where}: the design sends {low:.3g}-{high:.3g} '
                               f'({ref.unit or "SI"}) to {ref.name!r}, whose start value in '
                               f'the FMU is {start:.4g}: a factor {factor:.0f} apart; is the '
                               'unit right?')
        return out

    @contextlib.contextmanager
    def run_timeout(self, timeout_s: float, name: str) -> Iterator[None]:
        """A shorter limit per design within the block: none in this process.

        An FMU run in the worker's own process cannot be stopped; the isolated model's
        (:class:`~suspension_tuning.fmu.isolated.IsolatedFmuModel`) can.
        """
        yield

    def plausibility(self, budget_s: float | None = None
                     ) -> tuple[dict[str, dict[str, float]], list[str]]:
        """One run of the centre design per scenario, and warnings where it looks wrong.

        The check for mapped variables whose unit the FMU does not declare: a unit off
        by a factor (a volume in cm^3 taken as litres) shows as tyre loads that do not
        carry the vehicle or a seat vibration no road vehicle has.

        - Static load: the time mean of the four tyre forces, as a mass (N / g), against
          the mapping's ``vehicle_mass_kg`` (warned beyond ``STATIC_LOAD_TOLERANCE``).
        - Ride: each seat's BS 6841 W_b RMS against ``PLAUSIBLE_SEAT_RMS_MPS2``.

        Parameters
        ----------
        budget_s : float, optional
            Wall-clock time the runs may take in all, s (a run that hangs is stopped
            when it is spent, and the scenarios left are not run: warnings say so).
            Bounds the runs in child processes (:class:`~suspension_tuning.fmu.
            isolated.IsolatedFmuModel`) only.

        Returns
        -------
        numbers : dict
            Per scenario: ``static_load_kg``, and in ride ``a_rms_driver_mps2``,
            ``a_rms_passenger_mps2``.
        warnings : list of str
            One line each, with the numbers.
        """
        numbers: dict[str, dict[str, float]] = {}
        warnings: list[str] = self._start_value_warnings()
        mass = self.mapping.vehicle_mass_kg
        deadline = None if budget_s is None else time.monotonic() + budget_s
        for name in self.mapping.scenarios:
            x = np.full((1, 2), 0.5)  # the centre of the design space (tune's default start)
            left_s = None if deadline is None else deadline - time.monotonic()
            if left_s is not None and left_s <= 0.0:
                warnings.append(f'{name}: not run: the plausibility check\'s {budget_s:g} s '
                                '(plausibility_timeout_s) were spent')
                continue
            try:
                if left_s is None:
                    result = self.evaluate(name, x)
                else:
                    with self.run_timeout(max(0.1, round(left_s, 1)),  # 0.1 s: messages
                                          'the plausibility check\'s limit, '
                                          'plausibility_timeout_s'):
                        result = self.evaluate(name, x)
            except (FmuRunError, ValueError) as error:
                warnings.append(f'{name}: the run of the centre design failed ({error}); '
                                'check the units of the design parameters')
                continue
            fz = np.asarray(result.result.histories['tyre_fz_n'])[0]
            found = {'static_load_kg': float(np.mean(fz.sum(axis=0)) / GRAVITY_MPS2)}
            if mass is not None and abs(found['static_load_kg'] / mass - 1.0) > \
                    STATIC_LOAD_TOLERANCE:
                warnings.append(
                    f'{name}: the tyres carry {found["static_load_kg"]:.0f} kg on average, '
                    f'the mapping says vehicle_mass_kg {mass:g}: check the unit of tyre_fz')
            if name == 'ride':
                low, high = PLAUSIBLE_SEAT_RMS_MPS2
                for seat in ('driver', 'passenger'):
                    key = f'a_rms_{seat}_mps2'
                    value = float(result.metrics[0, result.metric_names.index(key)])
                    found[key] = value
                    if not low <= value <= high:
                        warnings.append(
                            f'ride: {seat} seat W_b RMS {value:.3g} m/s^2 at the centre '
                            f'design, outside {low:g}-{high:g} m/s^2 for a road vehicle: '
                            'check the units of the design parameters (gas volume) and of '
                            'acc_driver / acc_passenger')
            numbers[name] = found
        if mass is None:
            warnings.append('no vehicle_mass_kg in the mapping: the static tyre loads are not '
                            'checked against the vehicle')
        return numbers, warnings

    # ------------------------------------------------------------------ running
    def _slave(self, instance_name: str):
        md = self.model_description
        if md.fmiVersion == '2.0':
            from fmpy.fmi2 import FMU2Slave
            return FMU2Slave(guid=md.guid, unzipDirectory=self._unzipdir,
                             modelIdentifier=md.coSimulation.modelIdentifier,
                             instanceName=instance_name)
        from fmpy.fmi3 import FMU3Slave
        return FMU3Slave(guid=md.guid, unzipDirectory=self._unzipdir,
                         modelIdentifier=md.coSimulation.modelIdentifier,
                         instanceName=instance_name)

    def _set(self, slave, name: str, value) -> None:
        v = self.variables[name]
        vr = [v.valueReference]
        fmi3 = self.model_description.fmiVersion == '3.0'
        if v.type in REAL_TYPES:
            (slave.setFloat64 if fmi3 else slave.setReal)(vr, [float(value)])
        elif v.type == 'Boolean':
            slave.setBoolean(vr, [bool(value)])
        elif not fmi3:
            slave.setInteger(vr, [int(value)])
        else:
            setter = {'Int64': slave.setInt64, 'UInt64': slave.setUInt64}.get(
                v.type, getattr(slave, f'set{v.type}', slave.setInt32))
            setter(vr, [int(value)])

    def _parameter_values(self, sm: ScenarioMapping, x: np.ndarray) -> list[dict]:
        """FMU parameter values (FMU units) of each design: fixed, speed, design."""
        n = x.shape[1]
        phys = self.space.to_physical(x, n)
        si = {}
        for axle in design_mod.AXLES:
            si[self.space.damper.key(axle)] = phys.dpsf(axle)
            si[self.space.spring.key(axle)] = phys.spring(axle)
        # the variables of the design space: a preset's from x (eq. 4), the others at
        # their baselines.  The design's own variables (``driven``) set their parameters
        # first; a key at its baseline does not override a parameter one of them sets.
        driven = set(si)
        for v in self.space.catalogue:  # one named as a paper key (gas_volume_front) is it
            if v.name not in si:
                si[v.name] = np.full(len(x), v.baseline)
        if n in self.space.presets:
            low, high = self.space.bounds(n)
            values = design_mod.denormalise(x, low, high)
            for j, v in enumerate(self.space.presets[n][1]):
                if v.name not in sm.design:
                    raise ValueError(f'scenario {sm.name}: the {n}-variable design '
                                     f'({self.space.presets[n][0]}) sets {v.name}, which the '
                                     'mapping\'s design section does not map to an FMU '
                                     'parameter (docs/fmu.md)')
                si[v.name] = values[:, j]
            driven = {v.name for v in self.space.presets[n][1]}
        conv = self.conversions[sm.name]
        out = []
        for i in range(len(x)):
            values: dict[str, Any] = dict(sm.parameters)
            if sm.speed_parameter is not None:
                values[sm.speed_parameter.name] = conv['speed_parameter'].to_fmu(
                    sm.speed_kmh / 3.6)
            designed: dict[str, float] = {}
            for key, ref in sorted(sm.design.items(), key=lambda item: item[0] not in driven):
                if key not in driven and ref.name in designed:
                    continue  # a parameter the design's own variables set already
                value = float(conv[f'design.{key}'].to_fmu(si[key][i]))
                if ref.name in designed and not np.isclose(designed[ref.name], value,
                                                           rtol=1e-12, atol=0.0):
                    raise ValueError(f'design {i}: FMU parameter {ref.name!r} gets both '
                                     f'{designed[ref.name]!r} and {value!r} (front and rear '
                                     'differ: map them to two parameters or use 2 variables)')
                designed[ref.name] = value
            out.append({**values, **designed})
        return out

    def _road_inputs(self, sm: ScenarioMapping, t_rel: np.ndarray) -> np.ndarray:
        """Road elevation (FMU units) of each road input at times t_rel, (n, inputs).

        One column per FMU input variable (``RoadInputs.variables`` order): the track
        under its corner, or the mean of the tracks of the corners that share it (a
        per-axle input gets the mean of the left and right tracks).
        """
        ri, road = sm.road, self.roads[sm.name]
        x_rear = ri.start_rear_axle_at_m + sm.speed_kmh / 3.6 * t_rel
        x_front = x_rear + ri.wheelbase_m
        conv = self.conversions[sm.name]
        track = {}
        for c, x_axle in zip(CORNERS, (x_front, x_front, x_rear, x_rear)):
            track[c] = road.elevation(x_axle, 0 if c[1] == 'l' else 1)[0]
        cols = []
        for _name, (_ref, corners) in ri.variables().items():
            z = np.mean([track[c] for c in corners], axis=0)
            cols.append(conv[f'road.{corners[0]}'].to_fmu(z))
        return np.column_stack(cols)

    def _run_one(self, sm: ScenarioMapping, index: int, x: np.ndarray, values: dict,
                 inputs: np.ndarray | None, progress: Any = None) -> np.ndarray:
        """Outputs (n_outputs, n_steps + 1) in FMU units of one design on a fresh instance.

        ``progress`` (optional, e.g. a ``multiprocessing.RawValue('d')``): its ``value`` is
        set to the simulation time at the start of every step, s.
        """
        fmi3 = self.model_description.fmiVersion == '3.0'
        names = [ref.name for ref in sm.outputs.values()]
        out_vr = [self.variables[n].valueReference for n in names]
        in_vr = ([self.variables[name].valueReference for name in sm.road.variables()]
                 if inputs is not None else [])
        t0, h, n = sm.start_time_s, sm.step_size_s, sm.n_steps
        samples = np.empty((len(names), n + 1))
        slave = self._slave(f'design_{index}')
        get = slave.getFloat64 if fmi3 else slave.getReal
        put = slave.setFloat64 if fmi3 else slave.setReal
        t = t0
        fatal = False
        log = FmuLog(index, lambda: t, self.on_message)
        if progress is not None:
            progress.value = t0
        try:
            try:
                log.instantiate(slave, fmi3)
                for name, value in values.items():
                    self._set(slave, name, value)
                if fmi3:
                    slave.enterInitializationMode(startTime=t0, stopTime=sm.stop_time_s)
                else:
                    slave.setupExperiment(startTime=t0, stopTime=sm.stop_time_s)
                    slave.enterInitializationMode()
                if inputs is not None:
                    put(in_vr, inputs[0].tolist())
                slave.exitInitializationMode()
                samples[:, 0] = get(out_vr)
                for k in range(n):
                    t = t0 + k * h
                    if progress is not None:
                        progress.value = t
                    if inputs is not None:
                        put(in_vr, inputs[k].tolist())
                    status = slave.doStep(currentCommunicationPoint=t, communicationStepSize=h)
                    if fmi3 and status[1]:
                        raise RuntimeError(f'the FMU asked to terminate at t = {t + h:.6g} s')
                    samples[:, k + 1] = get(out_vr)
                    if not np.all(np.isfinite(samples[:, k + 1])):
                        bad = names[int(np.argmin(np.isfinite(samples[:, k + 1])))]
                        raise RuntimeError(f'output {bad!r} = {samples[names.index(bad), k + 1]}'
                                           f' at t = {t + h:.6g} s (diverged)')
                slave.terminate()
            except Exception as error:
                fatal = getattr(error, 'status', None) == FMI_FATAL
                raise
            finally:
                # After a fatal status FMI allows no further call on the instance (not
                # even freeing it): it is left as it is, with the logger it may still
                # call.  Its library stays loaded.
                if fatal:
                    _LOADED_LIBRARIES.append((slave, log))
                elif getattr(slave, 'component', None) is not None:
                    try:
                        slave.freeInstance()
                    except Exception:  # noqa: BLE001,S110 - a failed instance may not free
                        pass
        except Exception as error:  # noqa: BLE001 - every FMU failure names the design
            said = log.summary()
            cause = f'{str(error).rstrip(".")}.{said}' if said else str(error)
            raise FmuRunError(f'{design_label(index, x)}: the FMU failed at t = {t:.6g} s: '
                              f'{cause}') from error
        return samples

    def _run_designs(self, sm: ScenarioMapping, x: np.ndarray, values: list[dict],
                     inputs: np.ndarray | None) -> np.ndarray:
        """Outputs (m, n_outputs, n_steps + 1) in FMU units of each design, in order."""
        return np.stack([self._run_one(sm, i, x[i], values[i], inputs) for i in range(len(x))])

    def evaluate(self, scenario: str, designs: np.ndarray, controllers: Any = None,
                 **_: Any) -> DesignEvaluation:
        """Run a batch of normalised designs (m, n_vars) on the FMU, one instance each.

        Returns what :func:`suspension_tuning.evaluation.evaluate` returns: f (eq. 9 or
        10), g (eq. 11), named metrics and a ScenarioResult whose histories carry the
        simplified models' inputs (handling: steering and slip angles).

        Raises
        ------
        ValueError
            A scenario the mapping does not serve, or designs that do not fit it.
        FmuRunError
            A design's run failed (the message names the design).
        """
        if scenario not in self.mapping.scenarios:
            raise ValueError(f'scenario {scenario!r} is not served by this FMU worker; its '
                             f'mapping serves {", ".join(self.mapping.scenarios)}')
        if controllers is not None:
            raise ValueError('an FMU worker takes no valve controllers')
        sm = self.mapping.scenarios[scenario]
        x = design_mod.validate_design(designs, int(np.shape(designs)[-1]))
        values = self._parameter_values(sm, x)
        t_rel = sm.step_size_s * np.arange(sm.n_steps + 1)
        inputs = self._road_inputs(sm, t_rel) if sm.road is not None else None
        start = time.perf_counter()
        runs = self._run_designs(sm, x, values, inputs)
        wall = time.perf_counter() - start
        conv = self.conversions[scenario]
        # Each channel contiguous per design: reductions over a strided view sum in an
        # order that depends on the batch, and a design must give the same bits alone,
        # in a batch or in the calibration's chunks.
        ch = {key: np.ascontiguousarray(conv[f'outputs.{key}'].to_si(runs[:, j]))
              for j, key in enumerate(sm.outputs)}
        if scenario == 'ride':
            result = self._ride(sm, x, ch, wall)
        else:
            result = self._handling(sm, x, ch, sm.start_time_s + t_rel, wall)
        names, table = metric_table(result.metrics, len(x))
        return DesignEvaluation(f=np.asarray(result.f, float), g=np.asarray(result.g, float),
                                metric_names=names, metrics=table, result=result)

    @staticmethod
    def _wheels(ch: dict, key: str) -> np.ndarray:
        return np.stack([ch[f'{key}_{c}'] for c in CORNERS], axis=1)

    def _ride(self, sm: ScenarioMapping, x, ch, wall) -> scen.ScenarioResult:
        fz = self._wheels(ch, 'tyre_fz')
        f, g, met = scen.ride_objective(ch['acc_driver'], ch['acc_passenger'], fz,
                                        sm.step_size_s, sm.settle_s, ch.get('roll'),
                                        ch.get('roll_rate'))
        hist = {'t_s': sm.start_time_s + sm.step_size_s * np.arange(fz.shape[-1]),
                'acc_driver_mps2': ch['acc_driver'], 'acc_passenger_mps2': ch['acc_passenger'],
                'tyre_fz_n': fz}
        if 'speed' in ch:
            met['speed_mean_mps'] = np.mean(ch['speed'], axis=-1)
        return scen.ScenarioResult('ride', x, f, g, met, hist, wall,
                                   sm.stop_time_s - sm.start_time_s)

    def _handling(self, sm: ScenarioMapping, x, ch, t, wall) -> scen.ScenarioResult:
        batch = len(x)
        if sm.windows is not None:
            t_lc = tuple(np.full(batch, v) for v in sm.windows['first_lane_change_s'])
            t_man = tuple(np.full(batch, v) for v in sm.windows['manoeuvre_s'])
        else:
            track = self._track
            x0_lc, x1_lc = track.first_lane_change_x_m
            t_lc = tuple(scen.crossing_time(ch['x'], t, xs) for xs in (x0_lc, x1_lc))
            t_man = tuple(scen.crossing_time(ch['x'], t, xs) for xs in (0.0, track.x_end_m))
        f, g, met = scen.handling_objective(ch['roll'], ch['roll_rate'],
                                            self._wheels(ch, 'tyre_fz'), t, t_lc, t_man)
        speed = ch.get('speed', np.full((batch, t.size), sm.speed_kmh / 3.6))
        hist = {'t_s': t, 'roll_deg': np.degrees(ch['roll']),
                'roll_rate_deg_s': np.degrees(ch['roll_rate']),
                'tyre_fz_n': self._wheels(ch, 'tyre_fz'), 'steer_rad': ch['steer'],
                'slip_angle_rad': self._wheels(ch, 'slip_angle'), 'speed_mps': speed}
        if 'x' in ch:
            hist['x_m'] = ch['x']
        met['speed_min_mps'] = np.min(speed, axis=-1)
        return scen.ScenarioResult('handling', x, f, g, met, hist, wall,
                                   sm.stop_time_s - sm.start_time_s)

    def close(self) -> None:
        """Remove the FMU's extracted files (its library stays loaded, see below)."""
        library = getattr(self, '_library', None)
        if library is not None:
            # The shared library stays loaded for the process's life: an FMU that embeds
            # an interpreter (pythonfmu's, in this very process) leaves objects behind
            # whose later garbage collection calls into it, a crash once it is unloaded.
            _LOADED_LIBRARIES.append(library)
            self._library = None
        if getattr(self, '_unzipdir', None):
            shutil.rmtree(self._unzipdir, ignore_errors=True)
            self._unzipdir = None

    def __enter__(self) -> FmuModel:
        """Use as a context manager: closed on exit."""
        return self

    def __exit__(self, *exc) -> None:
        """Close the model."""
        self.close()
