"""Parses an OpenMetrics text exposition from stdin with the Prometheus
project's own parser (prometheus_client.openmetrics.parser, which checks
names, types, units, label syntax, histogram buckets and the # EOF) and
prints its families as JSON: [{name, type, unit, samples: [{name, labels,
value}]}]. Exits 1 with the parser's message if the text is not valid."""

import json
import sys

from prometheus_client.openmetrics.parser import text_string_to_metric_families

try:
    families = [
        {
            "name": family.name,
            "type": family.type,
            "unit": family.unit,
            "samples": [
                {"name": s.name, "labels": s.labels, "value": s.value}
                for s in family.samples
            ],
        }
        for family in text_string_to_metric_families(sys.stdin.read())
    ]
except ValueError as error:
    print(f"not valid OpenMetrics: {error}", file=sys.stderr)
    sys.exit(1)
json.dump(families, sys.stdout)
