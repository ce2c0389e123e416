#!/usr/bin/env bash
# Create a SimulationRun, wait until it is complete, report, and exit like `carlos run`:
#   0 every required criterion passed · 1 test failures · 3 errors, a failed Job or a timeout.
# Usage: run-simulation.sh MANIFEST [NAMESPACE] [TIMEOUT]   (MANIFEST uses metadata.generateName)
# Writes name=… and results=… to $GITHUB_OUTPUT when set. Needs kubectl (with a kubeconfig) and python3.
set -euo pipefail
manifest="${1:?usage: run-simulation.sh MANIFEST [NAMESPACE] [TIMEOUT]}"
namespace="${2:-carlos-runs}"
timeout="${3:-60m}"

if ! grep -q '^  generateName:' "$manifest"; then
  echo "error: $manifest: set metadata.generateName (each pipeline run creates a new SimulationRun)" >&2
  exit 2
fi
name="$(kubectl -n "$namespace" create -f "$manifest" -o 'jsonpath={.metadata.name}')"
echo "created simulationrun/$name in namespace $namespace"
if [ -n "${GITHUB_OUTPUT:-}" ]; then echo "name=$name" >>"$GITHUB_OUTPUT"; fi

# Complete is True once every run has finished, whether the run passed or not (then Failed is True too).
if ! kubectl -n "$namespace" wait "simulationrun/$name" --for=condition=Complete --timeout="$timeout"; then
  echo "error: simulationrun/$name did not complete within $timeout" >&2
  kubectl -n "$namespace" get simulationrun "$name" -o yaml >&2 || true
  exit 3
fi

status_file="$(mktemp)"
trap 'rm -f "$status_file"' EXIT
kubectl -n "$namespace" get simulationrun "$name" -o json >"$status_file"
python3 - "$status_file" <<'PY'
import json, os, sys

run = json.load(open(sys.argv[1]))
status = run.get("status") or {}
phase = status.get("phase")
name = run["metadata"]["name"]
print(
    f"simulationrun/{name}: {phase} · {status.get('progress', '?')} runs · {status.get('passed', 0)} passed, "
    f"{status.get('testFailures', 0)} test failures, {status.get('errors', 0)} errors"
)
results = status.get("resultsURL", "")
if results:
    print(f"results: {results} (junit.xml, summary.json)")
if os.environ.get("GITHUB_OUTPUT") and results:
    with open(os.environ["GITHUB_OUTPUT"], "a") as out:
        out.write(f"results={results}\n")
for failure in status.get("failures") or []:
    line = f"index {failure['index']} ({failure.get('scenario', '?')}): {failure.get('status', '')} {failure.get('reason', '')}"
    # GitHub Actions shows ::error:: lines as annotations
    print(f"::error title=SimulationRun {name}::{line}" if os.environ.get("GITHUB_ACTIONS") else line)
if phase == "Succeeded":
    sys.exit(0)
if phase == "Failed" and status.get("testFailures", 0) > 0:
    sys.exit(1)
sys.exit(3)
PY
