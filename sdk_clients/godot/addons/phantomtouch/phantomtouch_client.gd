class_name PhantomTouchClient
extends Node
## The phantomtouch service for a Godot 4 scene; the plugin adds it as the autoload
## [code]PhantomTouch[/code].
##
## The WebSocket ([WebSocketPeer]) is polled every frame in [method _process]: that is where
## messages are read, the newest [method move] of each contact is sent (at most one per
## contact per frame, latest wins), a ping goes out whenever nothing was sent for a quarter
## of the service's [code]watchdog_s[/code], and a lost connection is retried with
## exponential back-off. After each (re)connection the client says hello again, puts every
## contact that is still down back where it is now, and re-subscribes.
## When the welcome offers the service's contact lane ([code]"lane": {"port", "key"}[/code],
## the service's docs/lane.md) and [member use_contact_lane] is on, the moves sent each frame
## go as UDP datagrams ([PacketPeerUDP]) to that port on the service's host, which takes them
## without waiting behind its HTTP work. Everything else stays on the WebSocket, and so do a
## contact's moves until the service confirmed its down (each down carries an id for that)
## and the move [method up] sends first. The lane's refusals come as [signal error_received].
## No lane offered, a datagram the socket cannot send, or a key the lane refuses: moves go
## over the WebSocket. The lane closes with the connection; each reconnection opens its own.
## REST goes through [member rest] ([PhantomTouchRest], HTTPRequest nodes).
## [member server_url], [member token] and [member client_name] are read from the project
## settings "phantomtouch/..." (the plugin adds them) when the node enters the tree.
##
## Positions are cm on the armband: x around the forearm (0-3.8 cm on the default band),
## y along it (0 cm at the wrist end, 14.4 cm at the elbow end).

signal connection_changed(connected: bool)
signal state_received(state: Dictionary)
signal contacts_released(contacts: Array)
signal error_received(error: Dictionary)
signal reply_received(id: int, reply: Dictionary)

enum Phase { IDLE, CONNECTING, WAITING_WELCOME, CONNECTED, BACKING_OFF }

const PROTOCOL := 1
const POLICY_VIOLATION := 1008

@export var server_url := "http://127.0.0.1:8000"
## The service token; needed when the service listens off loopback.
@export var token := ""
@export var client_name := "godot"
@export var auto_connect := true
@export var reply_timeout_s := 5.0
@export var reconnect_initial_s := 0.1
@export var reconnect_max_s := 5.0
## Send moves over the service's contact lane when it offers one; off: all on the WebSocket.
@export var use_contact_lane := true

var rest: PhantomTouchRest
var phase := Phase.IDLE
## The newest welcome: protocol, server_time_s, watchdog_s, device.
var welcome: Dictionary = {}
## How many times the client reconnected after losing the socket.
var reconnects := 0
## How many moves went over the contact lane.
var lane_moves_sent := 0

var _ws := WebSocketPeer.new()
var _contacts := {}
var _moves := {}
var _pending := {}
var _next_id := 1
var _subscribed_hz := 0.0
var _attempt := 0
var _deadline_msec := 0
var _last_send_msec := 0
var _last_receive_msec := 0
var _ever_connected := false
var _clock_offset_s := 0.0
var _lane := PacketPeerUDP.new()
var _lane_key := ""


func _ready() -> void:
	server_url = ProjectSettings.get_setting("phantomtouch/server_url", server_url)
	token = ProjectSettings.get_setting("phantomtouch/token", token)
	client_name = ProjectSettings.get_setting("phantomtouch/client_name", client_name)
	rest = PhantomTouchRest.new()
	rest.name = "Rest"
	rest.base_url = server_url
	rest.token = token
	add_child(rest)
	if auto_connect:
		connect_to_service()


func _process(_delta: float) -> void:
	if phase == Phase.IDLE:
		return
	var now := Time.get_ticks_msec()
	if phase == Phase.BACKING_OFF:
		if now >= _deadline_msec:
			_open()
		return
	_ws.poll()
	var ready_state := _ws.get_ready_state()
	if ready_state == WebSocketPeer.STATE_CLOSED:
		var why := "closed (%d %s)" % [_ws.get_close_code(), _ws.get_close_reason()]
		if _ws.get_close_code() == POLICY_VIOLATION:
			push_warning("PhantomTouch: refused by %s: %s (check the token)" % [server_url, why])
		_lose(why)
		return
	if ready_state != WebSocketPeer.STATE_OPEN:
		if now > _deadline_msec:
			_lose("no connection within %s s" % reply_timeout_s)
		return
	if phase == Phase.CONNECTING:
		_ws.set_no_delay(true)
		_send({"type": "hello", "client": client_name, "protocol": PROTOCOL})
		phase = Phase.WAITING_WELCOME
		_deadline_msec = now + int(reply_timeout_s * 1000)
	while _lane_key != "" and _lane.get_available_packet_count() > 0:
		var answer: Variant = JSON.parse_string(_lane.get_packet().get_string_from_utf8())
		if answer is Dictionary:
			_on_lane_answer(answer)
	while _ws.get_available_packet_count() > 0:
		_last_receive_msec = now
		var parsed: Variant = JSON.parse_string(_ws.get_packet().get_string_from_utf8())
		if parsed is Dictionary:
			_dispatch(parsed)
	if phase == Phase.WAITING_WELCOME and now > _deadline_msec:
		_lose("no welcome within %s s" % reply_timeout_s)
	elif phase == Phase.CONNECTED:
		_tick(now)


func _exit_tree() -> void:
	disconnect_from_service()


## Opens the WebSocket; the client reconnects by itself until [method disconnect_from_service].
func connect_to_service() -> void:
	if phase == Phase.IDLE:
		_open()


## Closes the WebSocket: the service releases this client's contacts with their ramp.
func disconnect_from_service() -> void:
	if phase == Phase.IDLE:
		return
	var was_connected := phase == Phase.CONNECTED
	phase = Phase.IDLE
	_ws.close()
	_close_lane()
	_fail_pending("disconnected")
	if was_connected:
		connection_changed.emit(false)


func is_connected_to_service() -> bool:
	return phase == Phase.CONNECTED


## True while moves go over the service's contact lane.
func is_using_contact_lane() -> bool:
	return _lane_key != ""


## A contact touches down at (x_cm, y_cm); intensity 0-1, or negative for the default.
func down(contact: String, x_cm: float, y_cm: float, intensity: float = -1.0) -> void:
	_contacts[contact] = {"x_cm": x_cm, "y_cm": y_cm, "intensity": intensity}
	_moves.erase(contact)
	if phase == Phase.CONNECTED:
		_send(_down_message(contact))


## The contact's newest position; sent with this frame's poll, replacing an unsent move.
func move(contact: String, x_cm: float, y_cm: float) -> void:
	if not _contacts.has(contact):
		return
	_contacts[contact].x_cm = x_cm
	_contacts[contact].y_cm = y_cm
	if phase == Phase.CONNECTED:
		_moves[contact] = {"type": "move", "contact": contact, "x_cm": x_cm, "y_cm": y_cm}


## Lift-off, after the contact's newest move.
func up(contact: String) -> void:
	if not _contacts.has(contact):
		return
	_contacts.erase(contact)
	if phase != Phase.CONNECTED:
		return
	if _moves.has(contact):
		_send(_moves[contact])
		_moves.erase(contact)
	_send({"type": "up", "contact": contact})


## The contacts held down: {contact: Vector2(x_cm, y_cm)}.
func active_contacts() -> Dictionary:
	var out := {}
	for contact in _contacts:
		out[contact] = Vector2(_contacts[contact].x_cm, _contacts[contact].y_cm)
	return out


## Sends [param message] with a fresh id and waits for its reply ("ok", "pong" or "error").
func request(message: Dictionary) -> Dictionary:
	if phase != Phase.CONNECTED:
		return {"type": "error", "code": "transport", "message": "not connected"}
	var id := _next_id
	_next_id += 1
	var sent := message.duplicate()
	sent["id"] = id
	_pending[id] = Time.get_ticks_msec() + int(reply_timeout_s * 1000)
	_send(sent)
	var reply: Array = [0, {}]
	while reply[0] != id:
		reply = await reply_received
	return reply[1]


## Schedules a touch over the WebSocket, as POST /touch; the job is in the reply's "result".
func play(touch_request: Dictionary) -> Dictionary:
	var message := touch_request.duplicate()
	message["type"] = "play"
	return await request(message)


## Stops one job, or everything of every client when [param job_id] is null.
func stop(job_id: Variant = null) -> Dictionary:
	var message := {"type": "stop"}
	if job_id != null:
		message["job_id"] = job_id
	return await request(message)


## Asks for [signal state_received] at [param rate_hz] (0 stops); kept across reconnects.
func subscribe(rate_hz: float) -> Dictionary:
	var reply := await request({"type": "subscribe", "rate_hz": rate_hz})
	if reply.get("type") == "ok":
		_subscribed_hz = rate_hz
	return reply


func ping() -> Dictionary:
	return await request({"type": "ping"})


## The service's clock now (s), estimated from the newest welcome or pong.
func server_time_s() -> float:
	return _clock_offset_s + Time.get_ticks_usec() / 1e6


## A touch request for a preset by name (GET /presets), with optional overrides.
static func preset(preset_name: String, overrides: Dictionary = {}) -> Dictionary:
	var touch_request := {"preset": preset_name}
	if not overrides.is_empty():
		touch_request["overrides"] = overrides
	return touch_request


## A touch request for a pattern stored with PUT /patterns/{name}.
static func stored(pattern_name: String) -> Dictionary:
	return {"stored": pattern_name}


## A touch request for a short tap at (x_cm, y_cm): 150 Hz, like the "vr/tap" preset.
static func tap(x_cm: float, y_cm: float, intensity: float, duration_s := 0.15) -> Dictionary:
	return {
		"path": {"kind": "polyline", "points_cm": [[x_cm, y_cm]]},
		"duration_s": duration_s,
		"fade_in_s": 0.01,
		"fade_out_s": minf(0.08, duration_s / 2.0),
		"carrier": {"kind": "sine", "freq_hz": 150.0},
		"intensity": clampf(intensity, 0.0, 1.0),
	}


func _ws_url() -> String:
	var url := server_url.trim_suffix("/")
	url = url.replace("https://", "wss://").replace("http://", "ws://")
	return url + "/ws"


func _open() -> void:
	_ws = WebSocketPeer.new()
	if token != "":
		_ws.handshake_headers = PackedStringArray(["Authorization: Bearer " + token])
	var started := _ws.connect_to_url(_ws_url())
	phase = Phase.CONNECTING
	_deadline_msec = Time.get_ticks_msec() + int(reply_timeout_s * 1000)
	if started != OK:
		_lose("cannot connect: " + error_string(started))


func _lose(reason: String) -> void:
	var was_connected := phase == Phase.CONNECTED
	_ws.close()
	_close_lane()
	_moves.clear()
	_fail_pending(reason)
	var delay_s := minf(reconnect_max_s, reconnect_initial_s * pow(2.0, mini(_attempt, 16)))
	_attempt += 1
	phase = Phase.BACKING_OFF
	_deadline_msec = Time.get_ticks_msec() + int(delay_s * 1000)
	if was_connected:
		push_warning("PhantomTouch: lost %s: %s" % [server_url, reason])
		connection_changed.emit(false)


func _fail_pending(reason: String) -> void:
	var ids := _pending.keys()
	_pending.clear()
	for id in ids:
		reply_received.emit(id, {"type": "error", "code": "transport", "message": reason})


func _send(message: Dictionary) -> void:
	_ws.send_text(JSON.stringify(message))
	_last_send_msec = Time.get_ticks_msec()


func _down_message(contact: String) -> Dictionary:
	var c: Dictionary = _contacts[contact]
	var message := {"type": "down", "contact": contact, "x_cm": c.x_cm, "y_cm": c.y_cm}
	if c.intensity >= 0.0:
		message["intensity"] = c.intensity
	# Its moves take the lane once the service confirmed it (they must not overtake it).
	c["down_id"] = _next_id
	c["confirmed"] = false
	message["id"] = _next_id
	_next_id += 1
	return message


func _open_lane(host: String, offer: Variant) -> void:
	if not use_contact_lane or not offer is Dictionary:
		return
	var port := int(offer.get("port", 0))
	var key := str(offer.get("key", ""))
	var address := host if host.is_valid_ip_address() else IP.resolve_hostname(host, IP.TYPE_IPV4)
	if port < 1 or port > 65535 or key == "" or address == "":
		return
	_lane = PacketPeerUDP.new()
	if _lane.connect_to_host(address, port) == OK:
		_lane_key = key
	else:
		push_warning("PhantomTouch: the lane at %s:%d cannot be reached" % [address, port])


func _close_lane() -> void:
	_lane_key = ""
	_lane.close()


func _send_move(contact: String, message: Dictionary) -> void:
	var c: Dictionary = _contacts.get(contact, {})
	if _lane_key != "" and c.get("confirmed", false):
		var datagram := message.duplicate()
		datagram["key"] = _lane_key
		if _lane.put_packet(JSON.stringify(datagram).to_utf8_buffer()) == OK:
			lane_moves_sent += 1
			return
		push_warning("PhantomTouch: the lane cannot send; moves go over the WebSocket")
		_close_lane()
	_send(message)


func _on_lane_answer(answer: Dictionary) -> void:
	if answer.get("type") == "error":
		for field in answer.get("fields", []):
			if field is Dictionary and field.get("field") == "key":
				push_warning("PhantomTouch: the lane refused the key; moves go over the WebSocket")
				_close_lane()
	_dispatch(answer)


func _host() -> String:
	var rest_of_url := server_url.get_slice("://", 1).get_slice("/", 0)
	if rest_of_url.begins_with("["):
		return rest_of_url.get_slice("]", 0).trim_prefix("[")
	return rest_of_url.get_slice(":", 0)


func _on_welcome(message: Dictionary) -> void:
	welcome = message
	_clock_offset_s = float(message.get("server_time_s", 0.0)) - Time.get_ticks_usec() / 1e6
	phase = Phase.CONNECTED
	_attempt = 0
	if _ever_connected:
		reconnects += 1
	_ever_connected = true
	_close_lane()
	_open_lane(_host(), message.get("lane"))
	for contact in _contacts:
		_send(_down_message(contact))
	if _subscribed_hz > 0.0:
		_send({"type": "subscribe", "rate_hz": _subscribed_hz})
	connection_changed.emit(true)


func _dispatch(message: Dictionary) -> void:
	var kind: String = message.get("type", "")
	var id: Variant = message.get("id")
	if (id is int or id is float) and _pending.has(int(id)):
		_pending.erase(int(id))
		if kind == "pong":
			_clock_offset_s = float(message.server_time_s) - Time.get_ticks_usec() / 1e6
		reply_received.emit(int(id), message)
		return
	if kind == "ok" and (id is int or id is float):
		for contact in _contacts:
			if _contacts[contact].get("down_id", -1) == int(id):
				_contacts[contact]["confirmed"] = true
		return
	match kind:
		"welcome":
			_on_welcome(message)
		"pong":
			_clock_offset_s = float(message.server_time_s) - Time.get_ticks_usec() / 1e6
		"state":
			state_received.emit(message)
		"released":
			var released: Array = message.get("contacts", [])
			for contact in released:
				_contacts.erase(contact)
				_moves.erase(contact)
			contacts_released.emit(released)
		"error":
			push_warning("PhantomTouch: %s: %s" % [message.get("code"), message.get("message")])
			error_received.emit(message)


func _tick(now: int) -> void:
	for contact in _moves:
		_send_move(contact, _moves[contact])
	_moves.clear()
	var watchdog_s: float = welcome.get("watchdog_s", 2.0)
	var ping_msec := maxi(50, int(watchdog_s * 1000 / 4))
	if now - _last_send_msec >= ping_msec:
		_send({"type": "ping"})
	if now - _last_receive_msec > 4 * ping_msec + int(reply_timeout_s * 1000):
		_lose("the service stopped answering")
		return
	var expired := []
	for id in _pending:
		if now > _pending[id]:
			expired.append(id)
	for id in expired:
		_pending.erase(id)
		var why := "no reply within %s s" % reply_timeout_s
		reply_received.emit(id, {"type": "error", "code": "timeout", "message": why})
