// The phantomtouch wire protocol (docs/protocol.md): touch requests, WebSocket messages
// and the error the service answers. Positions are cm on the armband: x around the
// forearm (0-3.8 cm on the default band), y along it (0 at the wrist end, 14.4 at the elbow).
using System;
using System.Collections.Generic;

namespace PhantomTouch
{
    /// <summary>A request the service refused, or a failure to reach it.</summary>
    public class PhantomTouchException : Exception
    {
        /// <summary>The protocol's error code: invalid, unauthorized, not_found, too_large,
        /// rate_limited, busy, invalid_json, unknown_type; "transport" when the service
        /// could not be reached; "timeout" when it did not answer in time.</summary>
        public string Code { get; private set; }

        /// <summary>The HTTP status, or 0 for a WebSocket reply or a transport failure.</summary>
        public int Status { get; private set; }

        public PhantomTouchException(string code, string message, int status = 0, Exception inner = null)
            : base(message + " (" + code + (status != 0 ? ", HTTP " + status : "") + ")", inner)
        {
            Code = code;
            Status = status;
        }

        /// <summary>The exception for an error body <c>{"error": {code, message}}</c> or a WebSocket
        /// <c>{"type": "error", code, message}</c>.</summary>
        public static PhantomTouchException FromError(JsonObject error, int status)
        {
            var inner = error.GetObject("error") ?? error;
            return new PhantomTouchException(inner.GetString("code") ?? "error",
                                             inner.GetString("message") ?? "refused", status);
        }
    }

    /// <summary>A touch for POST /touch, POST /render and the WebSocket "play": a preset,
    /// a stored pattern, or a pattern given inline, with optional timing.</summary>
    public sealed class TouchRequest
    {
        public JsonObject Body { get; private set; }

        TouchRequest(JsonObject body) { Body = body; }

        /// <summary>A preset by name (GET /presets), e.g. "vr/tap" or "exp2/curved".</summary>
        public static TouchRequest Preset(string name, JsonObject overrides = null)
        {
            var body = new JsonObject().With("preset", name);
            if (overrides != null) body["overrides"] = overrides;
            return new TouchRequest(body);
        }

        /// <summary>A pattern stored with PUT /patterns/{name}.</summary>
        public static TouchRequest Stored(string name)
        {
            return new TouchRequest(new JsonObject().With("stored", name));
        }

        /// <summary>A TouchPattern given inline (path, speed_cm_s or duration_s, carrier ...).</summary>
        public static TouchRequest Pattern(JsonObject pattern)
        {
            var body = new JsonObject();
            foreach (var field in pattern) body[field.Key] = field.Value;
            return new TouchRequest(body);
        }

        /// <summary>A short tap at one point: 150 Hz sine, 10 ms in, 80 ms out (like the
        /// "vr/tap" preset), at a relative intensity 0-1.</summary>
        public static TouchRequest Tap(double xCm, double yCm, double intensity, double durationS = 0.15)
        {
            var point = new List<object> { xCm, yCm };
            var pattern = new JsonObject()
                .With("path", new JsonObject().With("kind", "polyline")
                                              .With("points_cm", new List<object> { point }))
                .With("duration_s", durationS)
                .With("fade_in_s", 0.01)
                .With("fade_out_s", Math.Min(0.08, durationS / 2))
                .With("carrier", new JsonObject().With("kind", "sine").With("freq_hz", 150.0))
                .With("intensity", Math.Max(0.0, Math.Min(1.0, intensity)));
            return new TouchRequest(pattern);
        }

        /// <summary>Start this many ms from now (0-60000).</summary>
        public TouchRequest StartInMs(double ms)
        {
            Body.Remove("start_at_s");
            Body["start_in_ms"] = ms;
            return this;
        }

        /// <summary>Start at this time on the server clock (GET /clock), s.</summary>
        public TouchRequest StartAtS(double serverTimeS)
        {
            Body.Remove("start_in_ms");
            Body["start_at_s"] = serverTimeS;
            return this;
        }

        public override string ToString() { return Json.Serialize(Body); }
    }

    /// <summary>Builders of the WebSocket messages a client sends.</summary>
    public static class Messages
    {
        public const int ProtocolVersion = 1;

        public static JsonObject Hello(string clientName)
        {
            return new JsonObject().With("type", "hello").With("client", clientName)
                                   .With("protocol", ProtocolVersion);
        }

        public static JsonObject Down(string contact, double xCm, double yCm, double intensity = double.NaN)
        {
            var m = new JsonObject().With("type", "down").With("contact", contact)
                                    .With("x_cm", xCm).With("y_cm", yCm);
            if (!double.IsNaN(intensity)) m["intensity"] = intensity;
            return m;
        }

        public static JsonObject Move(string contact, double xCm, double yCm, double intensity = double.NaN)
        {
            var m = new JsonObject().With("type", "move").With("contact", contact)
                                    .With("x_cm", xCm).With("y_cm", yCm);
            if (!double.IsNaN(intensity)) m["intensity"] = intensity;
            return m;
        }

        public static JsonObject Up(string contact)
        {
            return new JsonObject().With("type", "up").With("contact", contact);
        }

        public static JsonObject Play(TouchRequest request)
        {
            var m = new JsonObject().With("type", "play");
            foreach (var field in request.Body) m[field.Key] = field.Value;
            return m;
        }

        public static JsonObject Stop(string jobId = null)
        {
            var m = new JsonObject().With("type", "stop");
            if (jobId != null) m["job_id"] = jobId;
            return m;
        }

        public static JsonObject Ping() { return new JsonObject().With("type", "ping"); }

        public static JsonObject Subscribe(double rateHz)
        {
            return new JsonObject().With("type", "subscribe").With("rate_hz", rateHz);
        }
    }
}
