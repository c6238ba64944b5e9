"""Every tuning constant of the runtime core is documented in docs/constants.md as fixed by design.

The runtime core (gyro_thermal_comp/thermal/, gyro_thermal_comp/nodes/) has named numbers that shape
what it computes but are not settings. A robot team can only change settings, so a number that
depends on the sensor or the robot must be a setting. A new tuning constant must therefore either
be documented as fixed, with the reason it needs no tuning, or become a setting.
"""
import ast
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ('gyro_thermal_comp/thermal', 'gyro_thermal_comp/nodes')
DOC = REPO / 'docs' / 'constants.md'

# Exact facts, conversions, versions and message-defined codes: no tuning, nothing to document.
NOT_TUNING = {
    'NS_PER_S',             # nanoseconds per second: a unit conversion
    'CALIBRATION_VERSION',  # the MLR calibration file's format version
    'OK', 'WARN', 'ERROR',  # diagnostic levels, as diagnostic_msgs/DiagnosticStatus defines them
}

_CONSTANT_NAME = re.compile(r'[A-Z][A-Z0-9_]*')


def _is_number(node: ast.AST) -> bool:
    """An int or float literal, negative too (bool is no number here)."""
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        return _is_number(node.operand)
    return isinstance(node, ast.Constant) and type(node.value) in (int, float)


def _is_numeric(node: ast.AST) -> bool:
    """A numeric literal or a non-empty tuple of them."""
    if isinstance(node, ast.Tuple):
        return bool(node.elts) and all(_is_number(e) for e in node.elts)
    return _is_number(node)


def _numeric_names(body: list[ast.stmt]) -> set[str]:
    """UPPERCASE names that the statements of `body` bind to numeric literals: `X = 1.0`,
    `X: float = 1.0`, `X = Y = 2`, `X = (1, 2)` and `A, B = 1, 2`."""
    names = set()
    for stmt in body:
        if isinstance(stmt, ast.Assign):
            pairs = [(target, stmt.value) for target in stmt.targets]
        elif isinstance(stmt, ast.AnnAssign) and stmt.value is not None:
            pairs = [(stmt.target, stmt.value)]
        else:
            continue
        for target, value in pairs:
            if isinstance(target, ast.Tuple) and isinstance(value, ast.Tuple) and len(target.elts) == len(value.elts):
                pairs.extend(zip(target.elts, value.elts))
            elif isinstance(target, ast.Name) and _CONSTANT_NAME.fullmatch(target.id) and _is_numeric(value):
                names.add(target.id)
    return names


def core_constants() -> dict[str, set[str]]:
    """{module path: its numeric UPPERCASE constants}, at module level and in top-level classes."""
    found = {}
    for package in PACKAGES:
        for path in sorted((REPO / package).rglob('*.py')):
            tree = ast.parse(path.read_text(), filename=str(path))
            names = _numeric_names(tree.body)
            for node in tree.body:
                if isinstance(node, ast.ClassDef):
                    names |= _numeric_names(node.body)
            if names:
                found[str(path.relative_to(REPO))] = names
    return found


def test_the_collector_finds_the_core_constants():
    """The collector itself works: it finds known constants of each kind, so the test below cannot
    pass by finding nothing."""
    found = set().union(*core_constants().values())
    assert {'QUIET_S', 'HORIZONS_S', 'NIS_MEDIAN', 'NORM_NOISE', 'UNKNOWN_VARIANCE', 'OK', 'NS_PER_S'} <= found
    assert 'REASONS' not in found and 'FORMAT' not in found   # names and strings are no numbers


def test_every_tuning_constant_of_the_core_is_documented_as_fixed():
    """A new numeric constant in thermal/ or nodes/ must appear in docs/constants.md (as `NAME`), with
    why it is fixed by design, or become a setting; exact facts and conversions are in NOT_TUNING."""
    documented = set(re.findall(r'`([A-Z][A-Z0-9_]*)`', DOC.read_text()))
    missing = sorted(f'{module}: {name}' for module, names in core_constants().items()
                     for name in names - NOT_TUNING - documented)
    assert not missing, ('tuning constants not in docs/constants.md: document each as fixed (what it sets, '
                         'why it needs no tuning) or make it a setting:\n  ' + '\n  '.join(missing))


def test_docs_constants_names_only_constants_that_exist():
    """docs/constants.md names no constant that the core no longer has."""
    documented = set(re.findall(r'`([A-Z][A-Z0-9_]*)`', DOC.read_text()))
    source = '\n'.join(p.read_text() for package in PACKAGES for p in (REPO / package).rglob('*.py'))
    defined = set(re.findall(r'^\s*([A-Z][A-Z0-9_]*)\s*(?::[^=\n]*)?=', source, re.MULTILINE))
    assert not sorted(documented - defined), f'stale names in docs/constants.md: {sorted(documented - defined)}'
