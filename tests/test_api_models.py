"""The REST API's models: a bad option is refused by validation with the choices named, and
/docs (OpenAPI) shows what each route takes and returns."""


def test_a_bad_option_is_refused_with_the_choices_and_nothing_starts(client):
    for field, bad in (("law", "pn"), ("camera", "fisheye"), ("speed", "3")):
        r = client.post("/api/sortie/start", json={"scenario": "cv-top-to-bottom", field: bad})
        assert r.status_code == 422, r.text
        detail = r.json()["detail"]
        assert detail.startswith(f"{field}: Input should be"), detail
        for choice in client.get("/api/meta").json()[
            {"law": "laws", "camera": "camera_modes", "speed": "speeds"}[field]
        ]:
            assert f"'{choice}'" in detail
    assert client.get("/api/status").json()["state"] == "idle"
    r = client.post("/api/logs/x.mcap/refly", json={"law": "nope"})
    assert r.status_code == 422 and r.json()["detail"].startswith("law: ")


def test_openapi_shows_what_comes_back(client):
    paths = client.get("/openapi.json").json()["paths"]

    def returns(path: str, method: str) -> str:
        schema = paths[path][method]["responses"]["200"]["content"]["application/json"]["schema"]
        return schema.get("$ref", str(schema.get("items", {}).get("$ref")))

    assert returns("/api/meta", "get").endswith("/Meta")
    assert returns("/api/gains", "get").endswith("/GainsOut")
    assert returns("/api/gains/reset", "post").endswith("/GainsOut")
    assert returns("/api/status", "get").endswith("/Status")
    assert returns("/api/sortie/start", "post").endswith("/Status")
    assert returns("/api/live/start", "post").endswith("/LiveAck")
    assert returns("/api/scenarios", "get").endswith("/ScenarioSummary")
    law = client.get("/openapi.json").json()["components"]["schemas"]["StartRequest"]
    assert law["properties"]["law"]["enum"] == ["png", "pg", "ibvs", "apn"]
