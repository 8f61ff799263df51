"""``BEVFLOW_*`` variables as defaults for every ``bevflow serve`` flag."""

from __future__ import annotations

import pytest

from bevflow_services.cli.serve import load_service, parse_service_args, service_parser


def parse(name: str, argv: list[str], monkeypatch, **environ: str):
    for key, value in environ.items():
        monkeypatch.setenv(key, value)
    return parse_service_args(service_parser(name, load_service(name)), argv)


def test_variables_fill_flags_of_every_kind(monkeypatch) -> None:
    args = parse("tracker", [], monkeypatch, BEVFLOW_SITE="demo-hall", BEVFLOW_ID_FILE="/data/id",
                 BEVFLOW_CONNECT="tcp/a:7447, tcp/b:7447", BEVFLOW_NO_DRIFT="yes", BEVFLOW_TICK_MS="50",
                 BEVFLOW_MODE="client", BEVFLOW_SHARED_MEMORY="0")
    assert (args.site, str(args.id_file), args.connect) == ("demo-hall", "/data/id", ["tcp/a:7447", "tcp/b:7447"])
    assert (args.no_drift, args.tick_ms, args.mode, args.shared_memory) == (True, 50.0, "client", False)


def test_the_command_line_wins(monkeypatch) -> None:
    args = parse("tracker", ["--site", "example-hall", "--tick-ms", "80"], monkeypatch,
                 BEVFLOW_SITE="demo-hall", BEVFLOW_TICK_MS="50")
    assert (args.site, args.tick_ms) == ("example-hall", 80.0)


@pytest.mark.parametrize(("variable", "value", "message"), [
    ("BEVFLOW_MODE", "router", "choose from peer, client"),
    ("BEVFLOW_TICK_MS", "fast", "could not convert"),
    ("BEVFLOW_NO_DRIFT", "maybe", "give one of"),
])
def test_a_bad_value_names_the_variable(monkeypatch, capsys, variable: str, value: str, message: str) -> None:
    with pytest.raises(SystemExit) as stop:
        parse("tracker", ["--site", "demo-hall"], monkeypatch, **{variable: value})
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert f"{variable}={value!r}" in err and message in err


def test_help_says_so(capsys) -> None:
    with pytest.raises(SystemExit):
        service_parser("projector", load_service("projector")).parse_args(["--help"])
    assert "BEVFLOW_ID_FILE" in capsys.readouterr().out
