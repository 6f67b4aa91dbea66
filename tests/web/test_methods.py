"""OPTIONS answers 204 with Allow naming every method of the path, and a 405 names them all too."""

from __future__ import annotations


def test_options_and_405_name_every_method_of_the_path(app_client) -> None:
    r = app_client.options("/api/v1/studies/any-study")
    assert r.status_code == 204 and r.headers["allow"] == "DELETE, GET, OPTIONS, PATCH"
    assert app_client.options("/api/v1/me").headers["allow"] == "GET, OPTIONS"
    r = app_client.put("/api/v1/studies/any-study")
    assert r.status_code == 405 and r.headers["allow"] == "DELETE, GET, OPTIONS, PATCH"
    assert app_client.options("/no/such/path").status_code == 404
