"""Write the gateway's OpenAPI spec to docs/openapi.json (or check that it is current).

    python scripts/export_openapi.py           # regenerate docs/openapi.json
    python scripts/export_openapi.py --check   # exit 1 if docs/openapi.json is out of date
"""

from __future__ import annotations

import argparse
import sys

from bevflow_services.gateway.openapi import SPEC_PATH, render_spec


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="do not write; exit 1 if the committed spec differs")
    args = parser.parse_args(argv)
    spec = render_spec()
    current = SPEC_PATH.read_text(encoding="utf-8") if SPEC_PATH.exists() else None
    if args.check:
        if current != spec:
            print(f"{SPEC_PATH} is out of date; run: python scripts/export_openapi.py", file=sys.stderr)
            return 1
        return 0
    if current != spec:
        SPEC_PATH.write_text(spec, encoding="utf-8")
        print(f"wrote {SPEC_PATH}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
