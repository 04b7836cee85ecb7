"""/metrics of leases: how many are active, granted, released, expired and refused, and the
commands forbidden to their callers by surface (read from the LeaseBook and the Gate when
Prometheus scrapes; they count, the registry only reads)."""

from __future__ import annotations

from collections.abc import Callable, Iterator

from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from service.core.access.callers import Gate


class LeaseCollector(Collector):
    """Reads `gate()` (None until the service runs, or with leases off: nothing reported)."""

    def __init__(self, gate: Callable[[], Gate | None]) -> None:
        self._gate = gate

    def describe(self) -> Iterator[Metric]:
        return iter(())

    def collect(self) -> Iterator[Metric]:
        gate = self._gate()
        if gate is None:
            return
        counts = gate.book.counts
        yield GaugeMetricFamily("armfleet_leases_active", "leases held now", gate.book.active)
        for name, value, what in (
            ("granted", counts.granted, "leases granted"),
            ("released", counts.released, "leases given back by their holder or the admin"),
            ("expired", counts.expired, "leases that ran past their time to live"),
            ("refused", counts.refused, "lease requests refused: too few free worlds"),
        ):
            yield CounterMetricFamily(f"armfleet_leases_{name}", what, value=value)
        forbidden = CounterMetricFamily(
            "armfleet_forbidden",
            "commands refused because their caller may not command that world, by surface",
            labels=["source"],
        )
        for source, n in sorted(gate.forbidden.items()):
            forbidden.add_metric([source], n)
        yield forbidden
