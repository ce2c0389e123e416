//go:build tools

// Package tools pins the kwok controller that `make k8s` builds.
package tools

import _ "sigs.k8s.io/kwok/cmd/kwok"
