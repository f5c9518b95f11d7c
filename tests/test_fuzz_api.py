"""The REST API under schema-driven fuzzing (schemathesis over the app's own OpenAPI
document, with the token): no request may get a 5xx, and every response must match the
schema the document declares. 25 requests an operation by default, valid and invalid ones
(PEREGRINE_FUZZ_EXAMPLES=200 for a longer run)."""

import os
import time

import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
from schemathesis import GenerationMode
from schemathesis.checks import not_a_server_error, response_schema_conformance

from groundstation.app.server import GroundStation

POSITIVE, NEGATIVE = GenerationMode.POSITIVE, GenerationMode.NEGATIVE

# examples per operation; PEREGRINE_FUZZ_EXAMPLES raises it for a longer run
EXAMPLES = int(os.environ.get("PEREGRINE_FUZZ_EXAMPLES", "25"))


@pytest.fixture(scope="module")
def station(tmp_path_factory):
    d = tmp_path_factory.mktemp("fuzz")
    gs = GroundStation(port=0, data_dir=d, log_dir=d / "logs")
    yield gs
    gs.close()


@pytest.fixture(scope="module")
def api_schema(station):
    auth = {"Authorization": f"Bearer {station.token}"}
    return schemathesis.openapi.from_asgi("/openapi.json", station.app, headers=auth)


@pytest.mark.early
def test_rest_api_gives_no_server_error_and_keeps_its_schema(api_schema, station, fuzz_summary):
    """Every operation of the document: up to EXAMPLES generated requests each, valid and
    invalid ones (seeded)."""
    auth = {"Authorization": f"Bearer {station.token}"}
    tally = {"cases": 0, "failures": 0}
    failed: list[str] = []
    operations = [result.ok() for result in api_schema.get_all_operations()]
    assert len(operations) >= 25

    for op in operations:

        @given(case=op.as_strategy(POSITIVE) | op.as_strategy(NEGATIVE))
        @settings(
            max_examples=EXAMPLES,
            deadline=None,
            suppress_health_check=list(HealthCheck),
            derandomize=True,  # the same cases every run
            database=None,
        )
        def fuzz(case):
            tally["cases"] += 1
            try:
                case.call_and_validate(
                    headers=auth, checks=[not_a_server_error, response_schema_conformance]
                )
            except BaseException:
                tally["failures"] += 1
                raise

        t0 = time.perf_counter()
        try:
            fuzz()
        except BaseException as exc:  # schemathesis's FailureGroup is a BaseExceptionGroup
            if isinstance(exc, KeyboardInterrupt):
                raise
            failed.append(f"{op.label}: {exc}")
        if os.environ.get("PEREGRINE_FUZZ_TIMES"):
            print(f"{op.label}: {time.perf_counter() - t0:.2f} s")
    fuzz_summary("REST API (schemathesis)", tally["cases"], len(failed))
    assert not failed, "\n\n".join(failed)
