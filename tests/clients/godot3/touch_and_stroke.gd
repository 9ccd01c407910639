# Godot 3 headless script: the phantomtouch wire protocol spoken by a real game engine.
#
#   PHANTOMTOUCH_URL=http://127.0.0.1:8000 godot3-server --path . -s res://touch_and_stroke.gd
#
# POSTs a tap to /touch (HTTPRequest), then over the WebSocket (WebSocketClient, polled
# every frame at 90 fps): hello, welcome, a contact down at the wrist end, one move per
# frame along the forearm to y = 12 cm, up. With PHANTOMTOUCH_LANE=on the moves go over the
# contact lane the welcome offers instead (PacketPeerUDP, one datagram a move with the
# lane's key), and a move off the armband is sent there too, whose refusal must name the
# field ("LANE_REFUSED y_cm"). Prints "JOB <id>" and, when everything answered as the
# protocol says, the success marker; any failure prints FAILED and exits 1.
extends SceneTree

const MARKER := "PHANTOMTOUCH_GODOT3_OK"
const CONTACT := "godot3-stroke"

var base_url := ""
var ws := WebSocketClient.new()
var inbox := []
var open := false
var lane := PacketPeerUDP.new()
var lane_key := ""


func _init():
	base_url = OS.get_environment("PHANTOMTOUCH_URL")
	call_deferred("_run")


func _fail(why):
	print("FAILED " + str(why))
	quit(1)


func _frame():
	ws.poll()
	return yield(self, "idle_frame")


func _send(message):
	ws.get_peer(1).put_packet(to_json(message).to_utf8())


func _on_established(_protocol):
	open = true
	ws.get_peer(1).set_write_mode(WebSocketPeer.WRITE_MODE_TEXT)


func _on_data():
	var parsed = JSON.parse(ws.get_peer(1).get_packet().get_string_from_utf8())
	if parsed.error == OK and typeof(parsed.result) == TYPE_DICTIONARY:
		inbox.append(parsed.result)


func _send_move(message):
	if lane_key == "":
		_send(message)
		return
	message["key"] = lane_key
	var error = lane.put_packet(to_json(message).to_utf8())
	if error != OK:
		_fail("PacketPeerUDP.put_packet: %d" % error)


func _take(kind):
	for i in range(inbox.size()):
		if inbox[i].get("type") == kind:
			var message = inbox[i]
			inbox.remove(i)
			return message
	return null


func _run():
	if base_url == "":
		_fail("PHANTOMTOUCH_URL is not set")
		return
	Engine.target_fps = 90

	var http = HTTPRequest.new()
	root.add_child(http)
	var tap = {
		"path": {"kind": "polyline", "points_cm": [[1.9, 7.2]]},
		"duration_s": 0.15,
		"fade_in_s": 0.01,
		"fade_out_s": 0.08,
		"carrier": {"kind": "sine", "freq_hz": 150.0},
		"intensity": 0.5,
		"start_in_ms": 20,
	}
	var headers = ["Content-Type: application/json", "Accept: application/json"]
	var error = http.request(base_url + "/touch", headers, false, HTTPClient.METHOD_POST, to_json(tap))
	if error != OK:
		_fail("HTTPRequest.request: %d" % error)
		return
	var done = yield(http, "request_completed")
	if done[0] != HTTPRequest.RESULT_SUCCESS or done[1] != 202:
		_fail("POST /touch: result %d, HTTP %d: %s" % [done[0], done[1], done[3].get_string_from_utf8()])
		return
	var job = parse_json(done[3].get_string_from_utf8())
	print("JOB " + str(job["job_id"]))

	ws.connect("connection_established", self, "_on_established")
	ws.connect("data_received", self, "_on_data")
	error = ws.connect_to_url(base_url.replace("http://", "ws://") + "/ws")
	if error != OK:
		_fail("WebSocketClient.connect_to_url: %d" % error)
		return
	var deadline = OS.get_ticks_msec() + 5000
	while not open:
		if OS.get_ticks_msec() > deadline:
			_fail("no WebSocket connection")
			return
		yield(_frame(), "completed")
	_send({"type": "hello", "client": "godot3", "protocol": 1})
	var welcome = null
	while welcome == null:
		if OS.get_ticks_msec() > deadline:
			_fail("no welcome")
			return
		yield(_frame(), "completed")
		welcome = _take("welcome")
	print("WELCOME " + str(welcome["watchdog_s"]))

	_send({"type": "down", "contact": CONTACT, "x_cm": 1.9, "y_cm": 2.0, "intensity": 0.5, "id": 1})
	var ok = null
	while ok == null:
		if OS.get_ticks_msec() > deadline:
			_fail("no ok for down")
			return
		yield(_frame(), "completed")
		ok = _take("ok")
		var refused = _take("error")
		if refused != null:
			_fail("down refused: " + to_json(refused))
			return
	print("DOWN ok")
	if OS.get_environment("PHANTOMTOUCH_LANE") == "on":
		var offer = welcome.get("lane")
		if typeof(offer) != TYPE_DICTIONARY:
			_fail("the welcome offers no lane: " + to_json(welcome))
			return
		var host = base_url.replace("http://", "").split("/")[0].split(":")[0]
		error = lane.connect_to_host(host, int(offer["port"]))
		if error != OK:
			_fail("PacketPeerUDP.connect_to_host: %d" % error)
			return
		lane_key = offer["key"]
		print("LANE " + str(offer["port"]))
	var frames = 60
	for frame in range(1, frames + 1):
		_send_move({"type": "move", "contact": CONTACT, "x_cm": 1.9, "y_cm": 2.0 + 10.0 * frame / frames})
		yield(_frame(), "completed")
	if lane_key != "":
		_send_move({"type": "move", "contact": CONTACT, "x_cm": 1.9, "y_cm": 5000.0, "id": 3})
		deadline = OS.get_ticks_msec() + 5000
		while lane.get_available_packet_count() == 0:
			if OS.get_ticks_msec() > deadline:
				_fail("no answer from the lane")
				return
			yield(_frame(), "completed")
		var answer = parse_json(lane.get_packet().get_string_from_utf8())
		if typeof(answer) != TYPE_DICTIONARY or answer.get("type") != "error" or answer.get("id") != 3.0:
			_fail("the lane did not refuse the move: " + str(answer))
			return
		print("LANE_REFUSED " + answer["fields"][0]["field"])
	for _i in range(10):
		yield(_frame(), "completed")
	_send({"type": "up", "contact": CONTACT})
	_send({"type": "ping", "id": 2})
	var pong = null
	deadline = OS.get_ticks_msec() + 5000
	while pong == null:
		if OS.get_ticks_msec() > deadline:
			_fail("no pong")
			return
		yield(_frame(), "completed")
		pong = _take("pong")
	var refused = _take("error")
	if refused != null:
		_fail("the stroke was refused: " + to_json(refused))
		return
	print("PONG " + str(pong["server_time_s"]))
	ws.disconnect_from_host()
	lane.close()
	print(MARKER)
	quit(0)
