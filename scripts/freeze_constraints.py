"""Write constraints.txt: the exact versions of every package installed in this environment
(bevflow itself left out), which ./run and the container image install with.

    .venv-test/bin/python scripts/freeze_constraints.py           # after the tests pass on an upgrade
    .venv-test/bin/python scripts/freeze_constraints.py --check   # exit 1 if constraints.txt differs

Run it from the test environment (``./run test`` builds ``.venv-test``): the versions the whole
test suite passed on are the ones a site gets.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET = ROOT / "constraints.txt"
HEADER = """\
# The versions bevflow's tests passed on: ./run and docker/Dockerfile install with
# `pip install -c constraints.txt ...`. Regenerate from the test environment after upgrading:
#   .venv-test/bin/python scripts/freeze_constraints.py
"""


def frozen() -> str:
    lines = subprocess.run([sys.executable, "-m", "pip", "freeze", "--exclude-editable"],
                           check=True, capture_output=True, text=True).stdout.splitlines()
    kept = sorted((line for line in lines if line and not line.lower().startswith("bevflow")), key=str.lower)
    return HEADER + "\n".join(kept) + "\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if constraints.txt differs; write nothing")
    args = parser.parse_args()
    text = frozen()
    if args.check:
        same = TARGET.is_file() and TARGET.read_text() == text
        print("constraints.txt is current" if same else "constraints.txt differs from this environment")
        return 0 if same else 1
    TARGET.write_text(text)
    print(f"wrote {TARGET} ({text.count(chr(10)) - HEADER.count(chr(10))} packages)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
