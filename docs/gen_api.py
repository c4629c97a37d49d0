"""Write ``docs/api.md``: the API reference of anisosample, generated from its docstrings.

Imports the installed package, walks every public module (no leading underscore anywhere in the
dotted name), and lists per module its public names -- ``__all__`` where the module declares it,
otherwise the functions, classes and UPPERCASE constants defined in the module (or, for a
subpackage, re-exported from its private submodules) -- with their signatures and the first
paragraph of their docstrings. Classes also list the public methods and properties they define.

    python docs/gen_api.py [-o docs/api.md] [--check]

``--check`` writes nothing and exits 1 when the file on disk differs from what would be written.
The output is deterministic (sorted by module, then in source order), so ``git diff`` shows what
an API change did to the reference. ``make docs`` runs this script.
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import pkgutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = "anisosample"
# Modules that are not API: the command line has its own section in the guide.
SKIP = {"anisosample.cli"}
MAX_DEFAULT = 60  # characters of a default value's repr before it is cut


def first_paragraph(obj) -> str:
    """The first paragraph of ``obj``'s docstring, joined into one line ('' if none)."""
    doc = inspect.getdoc(obj) or ""
    para = doc.strip().split("\n\n", 1)[0]
    return " ".join(line.strip() for line in para.splitlines()).strip()


def signature(obj) -> str:
    """``(a, b=1, *, c=...)`` with annotations as written and long defaults elided ('' if none)."""
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):
        return ""
    params = []
    for p in sig.parameters.values():
        if p.annotation is not inspect.Parameter.empty:
            p = p.replace(annotation=_Raw(_annotation_text(p.annotation)))
        if p.default is not inspect.Parameter.empty:
            d = p.default
            text = d.__name__ if inspect.isclass(d) else repr(d)
            if len(text) > MAX_DEFAULT or "\n" in text or text.startswith("<"):
                text = "..."
            p = p.replace(default=_Raw(text))
        params.append(p)
    ret = sig.return_annotation
    if ret is not inspect.Signature.empty:
        ret = _Raw(_annotation_text(ret))
    try:
        sig = sig.replace(parameters=params, return_annotation=ret)
    except ValueError:
        pass
    return str(sig)


def _annotation_text(ann) -> str:
    if isinstance(ann, str):
        return ann
    arg = getattr(ann, "__forward_arg__", None)  # typing.ForwardRef
    if arg is not None:
        return arg
    if inspect.isclass(ann) and ann.__module__ == "builtins":
        return ann.__qualname__
    return inspect.formatannotation(ann)


class _Raw:
    """Prints as the given text (no quotes), for annotations and defaults in signatures."""

    def __init__(self, text: str):
        self.text = text

    def __repr__(self) -> str:
        return self.text


def public_modules() -> list[str]:
    """Every importable public module of the package, sorted."""
    pkg = importlib.import_module(PACKAGE)
    names = {PACKAGE}
    for info in pkgutil.walk_packages(pkg.__path__, prefix=PACKAGE + "."):
        parts = info.name.split(".")
        if any(p.startswith("_") for p in parts) or info.name in SKIP:
            continue
        names.add(info.name)
    return sorted(names)


def _defined_here(modname: str, obj, is_package: bool) -> bool:
    owner = getattr(obj, "__module__", None) or ""
    return owner == modname or (is_package and owner.startswith(modname + "."))


def public_names(mod) -> list[str]:
    """The names a module offers (``__all__`` if declared), in source order where possible."""
    if hasattr(mod, "__all__"):
        return [n for n in mod.__all__ if hasattr(mod, n)]
    is_package = hasattr(mod, "__path__")
    out = []
    for name, obj in vars(mod).items():
        if name.startswith("_") or inspect.ismodule(obj):
            continue
        if inspect.isclass(obj) or callable(obj):
            if _defined_here(mod.__name__, obj, is_package):
                out.append(name)
        elif name.isupper() and isinstance(obj, (str, int, float, tuple, frozenset, dict)):
            out.append(name)
    return out


def _class_members(cls) -> list[str]:
    lines = []
    for name, raw in vars(cls).items():
        if name.startswith("_"):
            continue
        obj = getattr(cls, name, raw)
        if isinstance(raw, property) or isinstance(inspect.getattr_static(cls, name), property):
            doc = first_paragraph(raw) or next(  # a property's docstring is not inherited
                (first_paragraph(vars(base)[name]) for base in cls.__mro__[1:]
                 if name in vars(base) and first_paragraph(vars(base)[name])), "")
            lines.append(f"  - `{name}` (property) — {doc or '(no docstring)'}")
        elif callable(obj) and not inspect.isclass(obj):
            lines.append(
                f"  - `{name}{signature(obj)}` — {first_paragraph(obj) or '(no docstring)'}"
            )
    return lines


def describe(modname: str, name: str, obj) -> list[str]:
    if inspect.isclass(obj):
        lines = [f"### class `{name}{signature(obj)}`", ""]
        lines.append(first_paragraph(obj) or "(no docstring)")
        members = _class_members(obj)
        if members:
            lines += ["", *members]
    elif callable(obj):
        lines = [f"### `{name}{signature(obj)}`", "", first_paragraph(obj) or "(no docstring)"]
    else:
        text = repr(obj)
        if len(text) > 200:
            text = text[:197] + "..."
        lines = [f"### `{name}`", "", f"Constant: `{text}`" if "`" not in text else text]
    return lines + [""]


def generate() -> str:
    pkg = importlib.import_module(PACKAGE)
    for name in dir(pkg):  # resolve the package's lazy (PEP 562) attributes
        getattr(pkg, name)
    out = [
        "# API reference",
        "",
        "<!-- Generated by docs/gen_api.py from the docstrings (make docs); do not edit. -->",
        "",
        f"Every public module of `{PACKAGE}` with its public names, their signatures and the first "
        "paragraph of their docstrings. Read the docstrings themselves (`help(...)`) for the "
        "rest; `docs/guide.md` shows the API at work.",
        "",
        "Modules: " + ", ".join(f"[`{m}`](#{m.replace('.', '')})" for m in public_modules()),
        "",
    ]
    failures = []
    for modname in public_modules():
        out += [f"## {modname}", ""]
        try:
            mod = importlib.import_module(modname)
        except Exception as exc:  # a module mid-edit should not hide the others
            failures.append(modname)
            out += [f"*Import failed: `{type(exc).__name__}: {exc}`*", ""]
            continue
        doc = first_paragraph(mod)
        if doc:
            out += [doc, ""]
        names = public_names(mod)
        if modname == PACKAGE:
            exported = [n for n, o in vars(pkg).items() if inspect.ismodule(o)
                        and not n.startswith("_") and o.__name__.startswith(PACKAGE)]
            out += ["Submodules available as attributes: "
                    + ", ".join(f"`{n}`" for n in exported) + ".", ""]
            out += ["`__version__` is the installed package version.", ""]
        parent = sys.modules.get(modname.rsplit(".", 1)[0]) if modname != PACKAGE else None
        shared = [n for n in names if parent is not None and parent.__name__ != PACKAGE
                  and getattr(parent, n, None) is getattr(mod, n)]
        if shared:
            out += [f"Documented under `{parent.__name__}`, which re-exports them: "
                    + ", ".join(f"`{n}`" for n in shared) + ".", ""]
        for name in names:
            if name not in shared:
                out += describe(modname, name, getattr(mod, name))
    if failures:
        print("gen_api: could not import " + ", ".join(failures), file=sys.stderr)
    return "\n".join(out).rstrip() + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-o", "--output", type=Path, default=ROOT / "docs" / "api.md")
    ap.add_argument("--check", action="store_true",
                    help="exit 1 if the output file is not up to date; write nothing")
    args = ap.parse_args(argv)
    text = generate()
    if args.check:
        current = args.output.read_text() if args.output.exists() else ""
        if current != text:
            print(f"{args.output} is out of date: run `make docs`", file=sys.stderr)
            return 1
        return 0
    args.output.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.output.with_suffix(".md.tmp")
    tmp.write_text(text)
    tmp.replace(args.output)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
