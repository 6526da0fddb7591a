"""A cluster that cannot start is never a silent pass: a failure under CI, a skip with the reason elsewhere."""
import pytest

from tests.cluster.unavailable import unavailable


def test_under_ci_an_unavailable_cluster_fails_with_the_reason(monkeypatch):
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="unavailable: slurmctld did not start"):
        unavailable("slurmctld did not start")


@pytest.mark.parametrize("ci", [None, "false"])
def test_elsewhere_an_unavailable_cluster_is_skipped_with_the_reason(monkeypatch, ci):
    if ci is None:
        monkeypatch.delenv("CI", raising=False)
    else:
        monkeypatch.setenv("CI", ci)
    with pytest.raises(pytest.skip.Exception, match="unavailable: no apt-get"):
        unavailable("no apt-get")
