"""REST routes, one module per topic, and the WebSocket endpoint."""
