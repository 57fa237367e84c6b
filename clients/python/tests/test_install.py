"""The package these tests import is the one `pip install ./clients/python` makes of this checkout."""

from __future__ import annotations

from pathlib import Path

import nusense

SOURCE = Path(__file__).resolve().parents[1] / "src" / "nusense"


def test_the_installed_package_is_this_checkouts_and_is_typed() -> None:
    installed = Path(nusense.__file__).resolve().parent
    assert installed != SOURCE, "the tests must import the installed package, not the source folder"
    names = sorted(p.name for p in SOURCE.iterdir() if p.is_file())
    assert "py.typed" in names
    assert sorted(p.name for p in installed.iterdir() if p.is_file()) == names
    for name in names:
        assert (installed / name).read_bytes() == (SOURCE / name).read_bytes(), (
            f"the installed {name} is not this checkout's: run scripts/setup test"
        )
