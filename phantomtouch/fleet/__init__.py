"""Many armbands and many players over NATS: armband nodes, gateways, registry, sync start.

See ``docs/fleet.md``. Nothing below the server imports this package; the server meets it
only where the command line attaches a node to a running service
(:func:`phantomtouch.fleet.node.attach`).
"""
