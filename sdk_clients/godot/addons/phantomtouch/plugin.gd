@tool
extends EditorPlugin
## Registers the PhantomTouch autoload and its project settings while the plugin is enabled.
##
## Settings (Project Settings, "phantomtouch/"): server_url, token, client_name.

const AUTOLOAD_NAME := "PhantomTouch"
const AUTOLOAD_PATH := "res://addons/phantomtouch/phantomtouch_client.gd"
const SETTINGS := {
	"phantomtouch/server_url": "http://127.0.0.1:8000",
	"phantomtouch/token": "",
	"phantomtouch/client_name": "godot",
}


func _enable_plugin() -> void:
	for setting in SETTINGS:
		if not ProjectSettings.has_setting(setting):
			ProjectSettings.set_setting(setting, SETTINGS[setting])
		ProjectSettings.set_initial_value(setting, SETTINGS[setting])
		ProjectSettings.add_property_info({"name": setting, "type": TYPE_STRING})
	ProjectSettings.save()
	add_autoload_singleton(AUTOLOAD_NAME, AUTOLOAD_PATH)


func _disable_plugin() -> void:
	remove_autoload_singleton(AUTOLOAD_NAME)
