module github.com/carlos-sim/carlos/tools/k8s/pause

go 1.22
