{{/* Name of the chart, overridable by nothing: the objects are always "carlos"-named. */}}
{{- define "carlos.name" -}}carlos{{- end -}}

{{/* Full name: the release name, with "-carlos" unless the release name already contains it. */}}
{{- define "carlos.fullname" -}}
{{- if contains "carlos" .Release.Name -}}
{{- .Release.Name | trunc 63 | trimSuffix "-" -}}
{{- else -}}
{{- printf "%s-carlos" .Release.Name | trunc 63 | trimSuffix "-" -}}
{{- end -}}
{{- end -}}

{{- define "carlos.labels" -}}
helm.sh/chart: {{ printf "%s-%s" .Chart.Name .Chart.Version | replace "+" "_" }}
{{ include "carlos.selectorLabels" . }}
app.kubernetes.io/version: {{ .Chart.AppVersion | quote }}
app.kubernetes.io/managed-by: {{ .Release.Service }}
app.kubernetes.io/part-of: carlos
{{- end -}}

{{- define "carlos.selectorLabels" -}}
app.kubernetes.io/name: {{ include "carlos.name" . }}
app.kubernetes.io/instance: {{ .Release.Name }}
app.kubernetes.io/component: operator
{{- end -}}

{{- define "carlos.serviceAccountName" -}}
{{- if .Values.serviceAccount.create -}}
{{- default (include "carlos.fullname" .) .Values.serviceAccount.name -}}
{{- else -}}
{{- required "serviceAccount.name: give the name of an existing ServiceAccount when serviceAccount.create is false" .Values.serviceAccount.name -}}
{{- end -}}
{{- end -}}

{{/* An image reference: repository@digest, else repository:tag (tag default: the chart's appVersion).
     Call with (dict "image" .Values.images.X "root" $). */}}
{{- define "carlos.image" -}}
{{- if .image.digest -}}
{{- printf "%s@%s" .image.repository .image.digest -}}
{{- else -}}
{{- printf "%s:%s" .image.repository (default .root.Chart.AppVersion .image.tag) -}}
{{- end -}}
{{- end -}}

{{/* The run pods' image pull secrets: the global list plus every run image's own, without repeats. */}}
{{- define "carlos.runPullSecrets" -}}
{{- $names := list -}}
{{- range .Values.imagePullSecrets -}}{{- $names = append $names . -}}{{- end -}}
{{- range $role := list "simcore" "bridge" "recorder" "detector" -}}
{{- range (index $.Values.images $role).pullSecrets -}}{{- $names = append $names . -}}{{- end -}}
{{- end -}}
{{- $names | uniq | join "," -}}
{{- end -}}

{{/* The default output URL of runs (empty when no bucket is set). */}}
{{- define "carlos.defaultOutputURL" -}}
{{- with .Values.objectStore -}}
{{- if and (not .bucket) (or .prefix .endpoint .credentialsSecret) -}}
{{- fail "objectStore: set objectStore.bucket too (prefix, endpoint and credentialsSecret are settings of the default bucket)" -}}
{{- end -}}
{{- if .bucket -}}
{{- if .prefix -}}s3://{{ .bucket }}/{{ .prefix }}{{- else -}}s3://{{ .bucket }}{{- end -}}
{{- end -}}
{{- end -}}
{{- end -}}

{{/*
RBAC: exactly what the operator touches, nothing more. The source is operator/carlos_operator/rbac.py
(NAMESPACED_RULES, CLUSTER_RULES); tests/test_helm.py checks that the rendered rules equal it. No wildcards.
Secrets: `get` only (the object-store credentials a run names, to read its per-index summaries and write
the run summary); never list or watch.
*/}}
{{- define "carlos.namespacedRules" -}}
- apiGroups: ["carlos.dev"]
  resources: ["simulationruns"]
  verbs: ["get", "list", "watch"]
- apiGroups: ["carlos.dev"]
  resources: ["simulationruns/status"]
  verbs: ["patch"]
- apiGroups: ["carlos.dev"]
  resources: ["simulationruns/finalizers"]
  verbs: ["update"]
- apiGroups: ["batch"]
  resources: ["jobs"]
  verbs: ["get", "list", "watch", "create", "patch", "delete"]
- apiGroups: [""]
  resources: ["configmaps"]
  verbs: ["get", "create", "delete"]
- apiGroups: [""]
  resources: ["pods"]
  verbs: ["list"]
- apiGroups: [""]
  resources: ["events"]
  verbs: ["create"]
{{- end -}}

{{/* Only in the namespaces of secretReferences.namespaces: runs there may name Secrets. */}}
{{- define "carlos.secretRules" -}}
- apiGroups: [""]
  resources: ["secrets"]
  verbs: ["get"]
{{- end -}}

{{/* Cluster-scoped, in both modes: kopf lists and watches namespaces to serve the ones it is given. */}}
{{- define "carlos.clusterRules" -}}
- apiGroups: [""]
  resources: ["namespaces"]
  verbs: ["get", "list", "watch"]
{{- end -}}
