"""The pythonfmu target: an lsc completion as a Python FMI 2.0 Co-Simulation FMU.

`build_pythonfmu` generates the model module (`_pythonfmu_source`), copies lsc,
the runtime package (`_runtime`, imported as ``<lsc copy>._fmu_runtime`` in
the FMU) and scipy's solvers (`_vendor`) next to it, lets pythonfmu build the
FMU and completes its model description (units, dependencies).
"""

import hashlib
import os
import shutil
import sys
import tempfile
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np

import lsc

from .._description import model_structure, unit_definitions
from .._model import _complete_at_start
from ._pythonfmu_source import _BUILD_PLACEHOLDER, _SLAVE, _model_source
from ._vendor import _vendor_ivp

__all__ = ["build_pythonfmu"]

_RUNTIME = Path(__file__).parent / "_runtime"


def build_pythonfmu(spec, dest):
    """Build the pythonfmu FMU of a resolved, checked `ModelSpec` (see `fmu_build.build_fmu`)."""
    from pythonfmu.builder import FmuBuilder

    # Solvability check on the real data before anything is written.
    dae = spec.linear_dae()
    span = (spec.experiment["start"], spec.experiment["stop"])
    completion = _complete_at_start(dae, spec, span)
    k_used = completion.k

    name = spec.name
    dest = Path(dest)
    final = dest if dest.suffix == ".fmu" and not dest.is_dir() else dest / f"{name}.fmu"
    folder = final.parent
    folder.mkdir(parents=True, exist_ok=True)
    _remove_stale_work_dirs(folder)
    model_text, interface = _model_source(spec, k_used, dae)
    build = _build_id(name, model_text)
    prefix = f"lscfmu_{build}"
    script_module, model_module, package = prefix, f"{prefix}_model", f"{prefix}_lsc"
    own_modules = {m for m in sys.modules if m == prefix or m.startswith(prefix + "_")}
    # Everything is made in a work folder next to the FMU and moved over it in one os.replace:
    # an interrupted build leaves the old FMU (or none), never a part of one.
    work = Path(tempfile.mkdtemp(prefix=f"{_WORK_PREFIX}{os.getpid()}-", dir=folder))
    src = work / "src"
    try:
        src.mkdir()
        _copy_runtime(src / package)
        (src / f"{model_module}.py").write_text(model_text.replace(_BUILD_PLACEHOLDER, build))
        (src / "requirements.txt").write_text(_requirements())
        script = src / f"{script_module}.py"
        script.write_text(_SLAVE.format(name=name, model_module=model_module, package=package,
                                        description=spec.description or f"{name}: lsc completion",
                                        start=spec.experiment["start"], stop=spec.experiment["stop"],
                                        step=spec.experiment["step"]))
        sys.path.insert(0, str(src))
        try:
            fmu = FmuBuilder.build_FMU(script, dest=work / f"{name}.fmu",
                                       project_files=[src / f"{model_module}.py", src / package, src / "requirements.txt"],
                                       canGetAndSetFMUstate=True, canSerializeFMUstate=True)
        finally:
            while str(src) in sys.path:  # pythonfmu's builder adds it once more and leaves it
                sys.path.remove(str(src))
            # pythonfmu imported the script (and with it the model and the lsc copy) to write the
            # description: drop those modules, and only those (their names are this build's own)
            for mod in [m for m in sys.modules if (m == prefix or m.startswith(prefix + "_")) and m not in own_modules]:
                del sys.modules[mod]
        _complete_model_description(Path(fmu), interface)
        with open(fmu, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(fmu, final)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return final


_WORK_PREFIX = ".lsc-build-"


_SPARSE_IMPORTS = ("from ._sparse_problem import", "from ._sparse import")


def _copy_runtime(dest, sparse=False):
    """Copy lsc (its solver parts only), scipy's solvers and the runtime package to the package `dest`.

    `sparse`: keep lsc's sparse set-up (a model of scipy.sparse coefficients); otherwise the copy never imports
    scipy.sparse.
    """
    shutil.copytree(Path(lsc.__file__).parent, dest, ignore=shutil.ignore_patterns("__pycache__", "gallery"))
    # The runtime needs neither the gallery (sympy) nor solve_ivp: importing
    # scipy.integrate in an embedded interpreter loads scipy._lib._uarray,
    # whose finalization crashes native hosts at exit (see _vendor_ivp).
    # A dense model needs no sparse set-up either (scipy.sparse.linalg aborted a native host at exit once).
    lines = (dest / "__init__.py").read_text().splitlines(keepends=True)
    dropped = ("from . import gallery", "from ._integrate import") + (() if sparse else _SPARSE_IMPORTS)
    kept = [line for line in lines if not line.startswith(dropped)]
    if len(lines) - len(kept) != len(dropped):  # lsc's __init__ changed shape: fail at build, not in the FMU
        raise RuntimeError(f"fmu_build could not strip the imports {dropped} from lsc/__init__.py")
    (dest / "__init__.py").write_text("".join(kept))
    # inside the FMU the runtime is a subpackage of the lsc copy (its `_lsc` imports lsc's public names from there),
    # with scipy's solvers in a subpackage of its own
    shutil.copytree(_RUNTIME, dest / "_fmu_runtime", ignore=shutil.ignore_patterns("__pycache__"))
    _vendor_ivp(dest / "_fmu_runtime" / "_scipy_ivp")


def _remove_stale_work_dirs(folder):
    """Remove work folders of builds whose process is gone (killed: no finally block ran)."""
    for path in folder.glob(_WORK_PREFIX + "*"):
        try:
            pid = int(path.name[len(_WORK_PREFIX):].split("-", 1)[0])
            os.kill(pid, 0)
        except ProcessLookupError:
            shutil.rmtree(path, ignore_errors=True)
        except (ValueError, PermissionError, OSError):
            continue  # not ours, or a live process of another user


def _build_id(name, model_text):
    """16 hex digits of a hash of everything that runs in the FMU: its module names."""
    digest = hashlib.sha256()
    for text in (name, model_text, _SLAVE):
        digest.update(text.encode("utf-8"))
    for path in sorted(_RUNTIME.glob("*.py")):  # (the runtime package is flat)
        digest.update(path.name.encode("utf-8") + path.read_bytes())
    for path in sorted(Path(lsc.__file__).parent.rglob("*.py")):
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def _requirements():
    """What the host's Python needs to run the FMU (the versions it was built with)."""
    import scipy

    import threadpoolctl

    return f"numpy>={np.__version__}\nscipy>={scipy.__version__}\nthreadpoolctl>={threadpoolctl.__version__}\n"





def _complete_model_description(fmu, interface):
    """Add what pythonfmu does not write from the interface table: units, UnitDefinitions, ModelStructure.

    pythonfmu wrote the variables from their registration, which follows the
    table (`fmu_build.targets._runtime._variables.register_variables`); each
    is checked against its row, so a description never declares what the FMU
    does not do.
    """
    with zipfile.ZipFile(fmu) as zf:
        contents = {n: zf.read(n) for n in zf.namelist()}
    root = ET.fromstring(contents["modelDescription.xml"])
    rows = interface.rows()
    written = root.find("ModelVariables").findall("ScalarVariable")
    found = [(sv.get("name"), int(sv.get("valueReference")), sv.get("causality"), sv.get("variability"), sv[0].tag)
             for sv in written]
    declared = [(v["name"], v["vr"], v["causality"], v["variability"], v["type"]) for v in rows]
    if found != declared:
        raise RuntimeError(f"pythonfmu wrote the variables {found}; the interface table declares {declared}")
    for sv, v in zip(written, rows):
        if v["unit"]:
            sv[0].set("unit", v["unit"])
    # UnitDefinitions goes right after CoSimulation (FMI 2.0 element order).
    root.insert(list(root).index(root.find("CoSimulation")) + 1, unit_definitions(rows))
    structure = root.find("ModelStructure")
    for child in list(structure):
        structure.remove(child)
    model_structure(structure, rows, {v["name"]: i for i, v in enumerate(rows, start=1)}, model_exchange=False)
    ET.indent(root)
    contents["modelDescription.xml"] = ET.tostring(root, encoding="UTF-8", xml_declaration=True)
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as zf:
        for n, data in contents.items():
            zf.writestr(n, data)


def _finish_description(fmu, units, reads):
    """Add `units` ({variable: unit}; lambda's is 1/s), UnitDefinitions, InitialUnknowns and the outputs'
    dependencies (`reads`: {output: inputs it reads}; no other output has direct feedthrough).

    For the sparse target (`fmu_build.targets.sparse_pythonfmu`), whose variables are not in an interface
    table (`_complete_model_description` does the same from the table for the dense one).
    """
    with zipfile.ZipFile(fmu) as zf:
        contents = {n: zf.read(n) for n in zf.namelist()}
    root = ET.fromstring(contents["modelDescription.xml"])
    units = dict(units)
    all_units = sorted(set(units.values()) | {"1/s"})
    units["lambda"] = "1/s"
    variables = root.find("ModelVariables")
    outputs, index_of = [], {}
    for i, sv in enumerate(variables.findall("ScalarVariable"), start=1):
        index_of[sv.get("name")] = i
        real = sv.find("Real")
        if real is not None and sv.get("name") in units:
            real.set("unit", units[sv.get("name")])
        if sv.get("causality") == "output":
            outputs.append((i, sv.get("name")))
    # UnitDefinitions goes right after CoSimulation (FMI 2.0 element order).
    unit_defs = ET.Element("UnitDefinitions")
    for u in all_units:
        ET.SubElement(unit_defs, "Unit", name=u)
    cs_index = list(root).index(root.find("CoSimulation"))
    root.insert(cs_index + 1, unit_defs)
    structure = root.find("ModelStructure")
    for child in list(structure):
        structure.remove(child)
    outs = ET.SubElement(structure, "Outputs")
    for i, name in outputs:
        # states and the residual have no direct feedthrough; custom outputs list the inputs they read
        depends = " ".join(str(index_of[u]) for u in reads.get(name, []))
        ET.SubElement(outs, "Unknown", index=str(i), dependencies=depends)
    init = ET.SubElement(structure, "InitialUnknowns")
    for i, _ in outputs:
        ET.SubElement(init, "Unknown", index=str(i))  # depends on the parameters (start values, lambda, ...)
    ET.indent(root)
    contents["modelDescription.xml"] = ET.tostring(root, encoding="UTF-8", xml_declaration=True)
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as zf:
        for n, data in contents.items():
            zf.writestr(n, data)
