class_name PhantomTouchRest
extends Node
## The REST routes of the phantomtouch service, through one HTTPRequest node per call.
##
## Every method is a coroutine: [code]var answer := await PhantomTouch.rest.touch(body)[/code].
## An answer is a Dictionary: [code]ok[/code] (bool), [code]status[/code] (HTTP status, 0 when
## no answer came), [code]data[/code] (the parsed JSON), [code]error[/code] (the protocol's
## error code and message, or the transport problem) and [code]body[/code] (raw bytes).

var base_url := "http://127.0.0.1:8000"
var token := ""
var timeout_s := 10.0


## POST /touch: a touch request (see [method PhantomTouchClient.tap] and the protocol).
func touch(touch_request: Dictionary) -> Dictionary:
	return await call_route(HTTPClient.METHOD_POST, "/touch", touch_request)


## POST /render: the touch as a WAV file (float32, one channel per actuator) in [code]body[/code].
func render_wav(touch_request: Dictionary) -> Dictionary:
	return await call_route(HTTPClient.METHOD_POST, "/render", touch_request, "audio/wav")


## POST /render as JSON: the plan and its curves (times_s, positions_cm, gains).
func render_plan(touch_request: Dictionary) -> Dictionary:
	return await call_route(HTTPClient.METHOD_POST, "/render", touch_request)


func job(job_id: Variant) -> Dictionary:
	return await call_route(HTTPClient.METHOD_GET, "/jobs/%s" % _segment(job_id))


func cancel_job(job_id: Variant) -> Dictionary:
	return await call_route(HTTPClient.METHOD_DELETE, "/jobs/%s" % _segment(job_id))


## POST /stop: every job and contact of every client off at once.
func stop_all() -> Dictionary:
	return await call_route(HTTPClient.METHOD_POST, "/stop")


func patterns() -> Dictionary:
	return await call_route(HTTPClient.METHOD_GET, "/patterns")


func get_pattern(pattern_name: String) -> Dictionary:
	return await call_route(HTTPClient.METHOD_GET, "/patterns/%s" % _segment(pattern_name))


func put_pattern(pattern_name: String, pattern: Dictionary) -> Dictionary:
	var path := "/patterns/%s" % _segment(pattern_name)
	return await call_route(HTTPClient.METHOD_PUT, path, pattern)


func delete_pattern(pattern_name: String) -> Dictionary:
	return await call_route(HTTPClient.METHOD_DELETE, "/patterns/%s" % _segment(pattern_name))


## POST /patterns/{name}/play, now or [param start_in_ms] from now.
func play_pattern(pattern_name: String, start_in_ms: float = -1.0) -> Dictionary:
	var body: Variant = null
	if start_in_ms >= 0.0:
		body = {"start_in_ms": start_in_ms}
	var path := "/patterns/%s/play" % _segment(pattern_name)
	return await call_route(HTTPClient.METHOD_POST, path, body)


func device() -> Dictionary:
	return await call_route(HTTPClient.METHOD_GET, "/device")


func presets() -> Dictionary:
	return await call_route(HTTPClient.METHOD_GET, "/presets")


func clock() -> Dictionary:
	return await call_route(HTTPClient.METHOD_GET, "/clock")


func health() -> Dictionary:
	return await call_route(HTTPClient.METHOD_GET, "/health")


## GET /metrics: Prometheus text in [code]body[/code].
func metrics() -> Dictionary:
	return await call_route(HTTPClient.METHOD_GET, "/metrics", null, "text/plain")


## One HTTP exchange with the service.
func call_route(
	method: HTTPClient.Method, path: String, body: Variant = null, accept := "application/json"
) -> Dictionary:
	var http := HTTPRequest.new()
	http.timeout = timeout_s
	add_child(http)
	var headers := PackedStringArray(["Accept: " + accept])
	var data := ""
	if body != null:
		headers.append("Content-Type: application/json")
		data = JSON.stringify(body)
	if token != "":
		headers.append("Authorization: Bearer " + token)
	var started := http.request(base_url.trim_suffix("/") + path, headers, method, data)
	if started != OK:
		http.queue_free()
		return _answer(false, 0, null, "transport: " + error_string(started), PackedByteArray())
	var done: Array = await http.request_completed
	http.queue_free()
	if done[0] != HTTPRequest.RESULT_SUCCESS:
		var why := "transport: HTTPRequest result %d" % done[0]
		return _answer(false, 0, null, why, PackedByteArray())
	var status: int = done[1]
	var raw: PackedByteArray = done[3]
	var parsed: Variant = null
	if raw.size() > 0 and accept == "application/json":
		parsed = JSON.parse_string(raw.get_string_from_utf8())
	var ok := status >= 200 and status < 300
	var error := ""
	if not ok:
		error = "HTTP %d" % status
		if parsed is Dictionary and parsed.get("error") is Dictionary:
			error = "%s: %s" % [parsed.error.get("code", ""), parsed.error.get("message", "")]
	return _answer(ok, status, parsed, error, raw)


func _answer(
	ok: bool, status: int, data: Variant, error: String, body: PackedByteArray
) -> Dictionary:
	return {"ok": ok, "status": status, "data": data, "error": error, "body": body}


func _segment(value: Variant) -> String:
	return str(value).uri_encode()
