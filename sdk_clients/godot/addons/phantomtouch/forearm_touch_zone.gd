class_name ForearmTouchZone
extends Area3D
## Put this Area3D on the avatar's forearm (a child of the forearm bone's BoneAttachment3D),
## with a CollisionShape3D that covers the skin under the armband. Fingertips (physics
## bodies or Area3Ds on the layers in [member Area3D.collision_mask]) that enter it touch
## down at their place on the armband, move with it every physics frame (the client sends
## the newest position once per frame) and lift off when they leave.
##
## The forearm is described in this node's local space (metres): where the band's wrist
## end (y = 0 cm) and elbow end (y = [member band_length_cm]) sit, the local direction
## across the forearm towards increasing x, and the width that the band's x range spans,
## centred on the wrist-elbow line. Points are projected onto that line and that direction
## and clamped onto the band.

## Where the armband's wrist end (y = 0 cm) sits, local space, m.
@export var wrist_end := Vector3.ZERO
## Where the armband's elbow end (y = band_length_cm) sits, local space, m.
@export var elbow_end := Vector3(0.0, 0.0, 0.144)
## Local direction across the forearm, towards increasing x.
@export var across_axis := Vector3.RIGHT
## Width across the forearm that maps to x = 0 .. band_width_cm, m.
@export var width_m := 0.038
@export var band_width_cm := 3.8
@export var band_length_cm := 14.4
@export_range(0.0, 1.0) var intensity := 0.6
## If set, only nodes in this group touch.
@export var toucher_group := ""
## Contact ids are this prefix, a dash and the toucher's instance id.
@export var contact_prefix := "forearm"
@export var client_path: NodePath = ^"/root/PhantomTouch"

var _touching := {}


func _ready() -> void:
	monitoring = true
	body_entered.connect(_on_toucher_entered)
	body_exited.connect(_on_toucher_exited)
	area_entered.connect(_on_toucher_entered)
	area_exited.connect(_on_toucher_exited)


func _physics_process(_delta: float) -> void:
	var client := _client()
	if client == null:
		return
	for toucher in _touching.keys():
		if not is_instance_valid(toucher):
			client.up(_touching[toucher])
			_touching.erase(toucher)
			continue
		var cm := to_armband_cm(toucher.global_position)
		client.move(_touching[toucher], cm.x, cm.y)


func _exit_tree() -> void:
	var client := _client()
	for toucher in _touching:
		if client != null:
			client.up(_touching[toucher])
	_touching.clear()


## Armband coordinates (x_cm, y_cm) of a point in global space.
func to_armband_cm(global_point: Vector3) -> Vector2:
	var p := to_local(global_point) - wrist_end
	var axis := elbow_end - wrist_end
	var length2 := axis.length_squared()
	if length2 < 1e-12:
		push_warning("ForearmTouchZone: wrist_end and elbow_end coincide")
		return Vector2.ZERO
	var along := p.dot(axis) / length2
	var across_dir := across_axis - axis * (across_axis.dot(axis) / length2)
	var across := 0.5
	if across_dir.length_squared() > 1e-12 and width_m > 0.0:
		across = p.dot(across_dir.normalized()) / width_m + 0.5
	return Vector2(
		clampf(across, 0.0, 1.0) * band_width_cm, clampf(along, 0.0, 1.0) * band_length_cm
	)


func _client() -> PhantomTouchClient:
	return get_node_or_null(client_path) as PhantomTouchClient


func _accepts(toucher: Node) -> bool:
	return toucher is Node3D and (toucher_group == "" or toucher.is_in_group(toucher_group))


func _on_toucher_entered(toucher: Node) -> void:
	var client := _client()
	if client == null or not _accepts(toucher) or _touching.has(toucher):
		return
	var contact := "%s-%d" % [contact_prefix, toucher.get_instance_id()]
	_touching[toucher] = contact
	var cm := to_armband_cm((toucher as Node3D).global_position)
	client.down(contact, cm.x, cm.y, intensity)


func _on_toucher_exited(toucher: Node) -> void:
	if not _touching.has(toucher):
		return
	var contact: String = _touching[toucher]
	_touching.erase(toucher)
	var client := _client()
	if client != null:
		client.up(contact)
