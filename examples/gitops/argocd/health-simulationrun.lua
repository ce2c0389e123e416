-- Argo CD health check for carlos.dev/SimulationRun: Progressing while it runs, Healthy when every required
-- criterion passed, Degraded when a run failed its criteria or ended in an error, Suspended while
-- spec.suspend holds it, Degraded too when its Job vanished before it finished (Unknown). Reads only the status the operator writes (phase, progress, conditions, counts).
local hs = {}

local function condition(status, kind)
  if status.conditions == nil then
    return nil
  end
  for _, c in ipairs(status.conditions) do
    if c.type == kind then
      return c
    end
  end
  return nil
end

local function counts(status)
  local text = ""
  if status.progress ~= nil then
    text = status.progress .. " runs finished"
  end
  if status.passed ~= nil or status.testFailures ~= nil or status.errors ~= nil then
    text = text .. (text ~= "" and "; " or "") .. (status.passed or 0) .. " passed, " ..
      (status.testFailures or 0) .. " failed, " .. (status.errors or 0) .. " errors"
  end
  return text
end

local status = obj.status
if status == nil or status.phase == nil then
  hs.status = "Progressing"
  hs.message = "Waiting for the CARLOS operator to accept the run"
  return hs
end

local failed = condition(status, "Failed")
if status.phase == "Failed" or (failed ~= nil and failed.status == "True") then
  hs.status = "Degraded"
  local message = ""
  if failed ~= nil and failed.message ~= nil and failed.message ~= "" then
    message = failed.message
  else
    message = counts(status)
  end
  if status.resultsURL ~= nil then
    message = message .. " (results: " .. status.resultsURL .. ")"
  end
  hs.message = message
  return hs
end

if status.phase == "Unknown" then
  local complete = condition(status, "Complete")
  hs.status = "Degraded"
  hs.message = (complete ~= nil and complete.message) or "the run's Job is gone before it finished"
  return hs
end

if status.phase == "Succeeded" then
  hs.status = "Healthy"
  hs.message = counts(status)
  return hs
end

if status.phase == "Suspended" then
  hs.status = "Suspended"
  hs.message = "Suspended (spec.suspend); " .. counts(status)
  return hs
end

hs.status = "Progressing"
local message = status.phase
local text = counts(status)
if text ~= "" then
  message = message .. ": " .. text
end
if status.active ~= nil and status.active > 0 then
  message = message .. ", " .. status.active .. " pods active"
end
hs.message = message
return hs
