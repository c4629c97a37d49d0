"""Fill in the measured numbers quoted in ``docs/reproduction.md`` from the experiments' JSON.

A quoted number is written after a marker that names where it comes from::

    slope <!-- json:results/w_fig6/w_fig6.json:fits.aligned.slope .2f -->-1.74

``PATH`` is relative to the repository root, ``KEY`` is a dotted path into the JSON (list
indices are integers, ``-1`` is the last element; a key that itself contains dots is matched
whole), the optional last word is a Python format spec (default ``.3g``). The text right after
the marker is the value: a number, ``true``/``false``, or ``not yet measured`` while the JSON does
not exist. Nobody types these numbers: ``make docs`` (this script with ``--write``) rewrites every
value from the JSON files that exist, and ``tests/test_docs.py`` checks that each quoted number
matches its JSON to the digits written.

    python docs/fill_numbers.py            # list every marker with its quoted and current value
    python docs/fill_numbers.py --write    # rewrite the values in place (only where a JSON exists)
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "reproduction.md"
NOT_YET = "not yet measured"
# <!-- json:PATH:KEY[ FORMAT] -->VALUE
MARKER = re.compile(
    r"<!-- json:(?P<path>[^:\s]+):(?P<key>[^>]+?)(?:\s+(?P<fmt>[-+ #0-9,._]*[a-zA-Z%]))?\s*-->"
    r"(?P<value>not yet measured|true|false|[-+]?(?:\d+(?:\.\d+)?|\.\d+)(?:[eE][-+]?\d+)?)"
)


class MissingKey(KeyError):
    pass


def resolve(data, key: str):
    """``data[k1][k2]...`` for the dotted ``key``; dict keys containing dots are matched whole."""
    if key == "":
        return data
    if isinstance(data, dict):
        parts = key.split(".")
        for i in range(len(parts), 0, -1):  # longest key first
            head = ".".join(parts[:i])
            if head in data:
                return resolve(data[head], ".".join(parts[i:]))
        raise MissingKey(key)
    if isinstance(data, list):
        head, _, rest = key.partition(".")
        try:
            return resolve(data[int(head)], rest)
        except (ValueError, IndexError):
            raise MissingKey(key) from None
    raise MissingKey(key)


def format_value(value, fmt: str | None) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if not isinstance(value, (int, float)):
        raise TypeError(f"not a number: {value!r}")
    if fmt is None:
        fmt = "d" if isinstance(value, int) else ".3g"
    text = format(value, fmt)
    return text.replace("e+0", "e+").replace("e-0", "e-")


def markers(text: str):
    """Every marker in ``text`` as a match object."""
    return list(MARKER.finditer(text))


def current(match, root: Path = ROOT):
    """(new value text or None when the JSON does not exist, error message or None)."""
    path = root / match["path"]
    if not path.exists():
        return None, None
    try:
        data = json.loads(path.read_text())
        return format_value(resolve(data, match["key"].strip()), match["fmt"]), None
    except MissingKey:
        return None, f"{match['path']} has no key {match['key'].strip()!r}"
    except (TypeError, json.JSONDecodeError) as exc:
        return None, f"{match['path']}:{match['key'].strip()}: {exc}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--doc", type=Path, default=DOC)
    ap.add_argument("--write", action="store_true", help="rewrite the values in place")
    ap.add_argument("--root", type=Path, default=ROOT, help="where the JSON paths start")
    args = ap.parse_args(argv)
    text = args.doc.read_text()
    errors, pieces, last, changed = [], [], 0, 0
    for m in markers(text):
        new, err = current(m, args.root)
        if err:
            errors.append(err)
        shown = new if new is not None else m["value"]
        if new is not None and new != m["value"]:
            changed += 1
        if not args.write:
            print(f"{m['path']}:{m['key'].strip()}  quoted {m['value']!r}  json {new!r}")
        pieces += [text[last:m.start("value")], shown]
        last = m.end("value")
    pieces.append(text[last:])
    if args.write and changed:
        tmp = args.doc.with_suffix(".md.tmp")
        tmp.write_text("".join(pieces))
        tmp.replace(args.doc)
    print(f"{len(markers(text))} markers, {changed} {'updated' if args.write else 'stale'}")
    for err in errors:
        print("error: " + err, file=sys.stderr)
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
