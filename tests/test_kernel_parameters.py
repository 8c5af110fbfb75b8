"""No numba kernel takes more than MAX_PARAMETERS parameters: a kernel that needs more takes
named records (NamedTuple of arrays and scalars) instead.

The kernels listed in WIDER predate the rule: the debt still to pay down (the list should
only shrink; their parameter counts are in the comments). The check reads the source (ast), so
it costs no compilation. ``python tests/test_kernel_parameters.py`` prints the list as the
code stands.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("jassy", "ugens", "physics", "patches")
MAX_PARAMETERS = 10
#: Kernels written before the rule, (file, function), with their parameter counts.
WIDER: set[tuple[str, str]] = set()


def _is_kernel(node: ast.FunctionDef) -> bool:
    """Decorated with numba.njit / jit / cfunc (in any spelling)."""
    for dec in node.decorator_list:
        target = dec.func if isinstance(dec, ast.Call) else dec
        name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
        if name in ("njit", "jit", "cfunc"):
            return True
    return False


def kernel_parameters() -> dict[tuple[str, str], int]:
    """Parameters of every numba kernel in the packages, by (file relative to the root, name)."""
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            tree = ast.parse(path.read_text(), filename=str(path))
            for node in ast.walk(tree):
                if isinstance(node, ast.FunctionDef) and _is_kernel(node):
                    found[(path.relative_to(ROOT).as_posix(), node.name)] = _count(node)
    return found


def _count(node: ast.FunctionDef) -> int:
    """Parameters of a function definition: positional-only, positional and keyword-only."""
    args = node.args
    return len(args.posonlyargs) + len(args.args) + len(args.kwonlyargs)


def test_kernels_take_at_most_ten_parameters():
    found = kernel_parameters()
    assert len(found) > 100  # the scan sees the kernels
    wide = {key: n for key, n in found.items() if n > MAX_PARAMETERS and key not in WIDER}
    assert not wide, (
        f"numba kernels with more than {MAX_PARAMETERS} parameters: "
        + ", ".join(f"{file}:{name} ({n})" for (file, name), n in sorted(wide.items()))
        + "; pass named records (typing.NamedTuple of the arrays and scalars) instead"
    )
    # the list only shrinks: a kernel brought to ten or fewer, renamed or removed leaves it
    stale = sorted(key for key in WIDER if found.get(key, 0) <= MAX_PARAMETERS)
    assert not stale, f"no longer wider than {MAX_PARAMETERS}, remove from WIDER: {stale}"


def test_the_scan_counts_parameters_and_finds_kernels():
    source = "import numba\n@numba.njit(cache=True)\ndef f(a, /, b, *, c):\n    pass\ndef g(x):\n    pass\n"
    tree = ast.parse(source)
    kernels = [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef) and _is_kernel(n)]
    assert [k.name for k in kernels] == ["f"]
    assert _count(kernels[0]) == 3


if __name__ == "__main__":
    print("WIDER = {")
    for (file, name), count in sorted(kernel_parameters().items()):
        if count > MAX_PARAMETERS:
            print(f'    ("{file}", "{name}"),  # {count}')
    print("}")
