// The phantomtouch client: every REST route, and the WebSocket session for live contacts.
//
// It knows the routes, bodies and answers; the HTTP exchange itself is an IHttpTransport
// (UnityWebRequestTransport in Unity, an HttpClient one elsewhere), so the same class
// runs in a game and in a console program. Nothing here touches UnityEngine.
using System;
using System.Collections.Generic;
using System.Text;
using System.Threading.Tasks;

namespace PhantomTouch
{
    /// <summary>One HTTP answer as the transport saw it.</summary>
    public sealed class HttpAnswer
    {
        /// <summary>HTTP status; 0 when no answer came (see Error).</summary>
        public int Status;
        public byte[] Body = new byte[0];
        /// <summary>Why no answer came (DNS, refused, timeout ...), or null.</summary>
        public string Error;

        public string Text { get { return Encoding.UTF8.GetString(Body); } }
    }

    /// <summary>Sends one HTTP request. Implementations: UnityWebRequestTransport (Unity),
    /// or any HttpClient-based one.</summary>
    public interface IHttpTransport
    {
        /// <param name="method">GET, POST, PUT or DELETE.</param>
        /// <param name="url">Absolute URL.</param>
        /// <param name="jsonBody">The JSON body, or null for none.</param>
        /// <param name="headers">Headers to send (Accept, Authorization).</param>
        Task<HttpAnswer> SendAsync(string method, string url, string jsonBody, IDictionary<string, string> headers);
    }

    public sealed class PhantomTouchClient : IDisposable
    {
        readonly IHttpTransport http;

        /// <summary>The service, e.g. "http://127.0.0.1:8000".</summary>
        public string BaseUrl { get; private set; }
        /// <summary>The service token (needed when it listens off loopback), or null.</summary>
        public string Token { get; private set; }
        /// <summary>The live session once Connect was called, else null.</summary>
        public WebSocketSession Session { get; private set; }

        public PhantomTouchClient(string baseUrl, IHttpTransport http, string token = null)
        {
            BaseUrl = baseUrl.TrimEnd('/');
            Token = string.IsNullOrEmpty(token) ? null : token;
            this.http = http;
        }

        /// <summary>The WebSocket address: http -> ws, https -> wss, path /ws.</summary>
        public Uri WebSocketUri
        {
            get
            {
                var b = new UriBuilder(BaseUrl + "/ws");
                b.Scheme = b.Scheme == "https" ? "wss" : "ws";
                return b.Uri;
            }
        }

        /// <summary>Opens the WebSocket session (in the background; it reconnects by itself).
        /// useLane: send moves over the service's contact lane when it offers one (see
        /// WebSocketSession.UseLane).</summary>
        public WebSocketSession Connect(string clientName = "phantomtouch-csharp", bool useLane = true)
        {
            if (Session != null) return Session;
            Session = new WebSocketSession(WebSocketUri, Token, clientName) { UseLane = useLane };
            Session.Start();
            return Session;
        }

        /// <summary>Closes the WebSocket session; the server releases its contacts with their ramp.</summary>
        public void Disconnect()
        {
            var session = Session;
            Session = null;
            if (session != null) session.Dispose();
        }

        public void Dispose() { Disconnect(); }

        // Live contacts (WebSocket; they never block the caller).
        public void Down(string contact, double xCm, double yCm, double intensity = double.NaN) { Require().Down(contact, xCm, yCm, intensity); }
        public void Move(string contact, double xCm, double yCm, double intensity = double.NaN) { Require().Move(contact, xCm, yCm, intensity); }
        public void Up(string contact) { Require().Up(contact); }

        WebSocketSession Require()
        {
            if (Session == null) throw new InvalidOperationException("call Connect() before sending contacts");
            return Session;
        }

        // REST.

        /// <summary>POST /touch: schedules a touch; answers the job (job_id, start_at_s, duration_s ...).</summary>
        public Task<JsonObject> TouchAsync(TouchRequest request) { return ObjectAsync("POST", "/touch", request.Body); }

        /// <summary>POST /armbands/{armband}/touch of a fleet gateway (docs/fleet.md): the touch on one named armband.</summary>
        public Task<JsonObject> ArmbandTouchAsync(string armband, TouchRequest request) { return ObjectAsync("POST", "/armbands/" + Segment(armband) + "/touch", request.Body); }

        /// <summary>POST /render: the touch as a WAV file (float32, one channel per actuator).</summary>
        public Task<byte[]> RenderWavAsync(TouchRequest request) { return BytesAsync("POST", "/render", request.Body, "audio/wav"); }

        /// <summary>POST /render as JSON: the plan and its curves (times_s, positions_cm, gains).</summary>
        public Task<JsonObject> RenderPlanAsync(TouchRequest request) { return ObjectAsync("POST", "/render", request.Body); }

        /// <summary>GET /jobs/{id}: job_id, state (scheduled, playing, finished, stopped) ...</summary>
        public Task<JsonObject> JobAsync(object jobId) { return ObjectAsync("GET", "/jobs/" + Segment(jobId), null); }

        /// <summary>DELETE /jobs/{id}: stops that job with its release ramp.</summary>
        public Task<JsonObject> CancelJobAsync(object jobId) { return ObjectAsync("DELETE", "/jobs/" + Segment(jobId), null); }

        /// <summary>POST /stop: every job and contact of every client off at once.</summary>
        public Task<object> StopAsync() { return ValueAsync("POST", "/stop", null); }

        /// <summary>GET /patterns: [{name, summary}].</summary>
        public Task<object> PatternsAsync() { return ValueAsync("GET", "/patterns", null); }

        public Task<JsonObject> GetPatternAsync(string name) { return ObjectAsync("GET", "/patterns/" + Segment(name), null); }

        /// <summary>PUT /patterns/{name}: stores a TouchPattern (names: [A-Za-z0-9._-]{1,64}).</summary>
        public Task<object> PutPatternAsync(string name, JsonObject pattern) { return ValueAsync("PUT", "/patterns/" + Segment(name), pattern); }

        public Task<object> DeletePatternAsync(string name) { return ValueAsync("DELETE", "/patterns/" + Segment(name), null); }

        /// <summary>POST /patterns/{name}/play, now or startInMs from now.</summary>
        public Task<JsonObject> PlayPatternAsync(string name, double startInMs = double.NaN)
        {
            var body = double.IsNaN(startInMs) ? null : new JsonObject().With("start_in_ms", startInMs);
            return ObjectAsync("POST", "/patterns/" + Segment(name) + "/play", body);
        }

        public Task<JsonObject> DeviceAsync() { return ObjectAsync("GET", "/device", null); }
        public Task<object> PresetsAsync() { return ValueAsync("GET", "/presets", null); }
        /// <summary>GET /clock: server_time_s, frames, sample_rate_hz, unix_time_s.</summary>
        public Task<JsonObject> ClockAsync() { return ObjectAsync("GET", "/clock", null); }
        public Task<JsonObject> HealthAsync() { return ObjectAsync("GET", "/health", null); }

        /// <summary>GET /metrics: Prometheus text.</summary>
        public async Task<string> MetricsAsync()
        {
            var bytes = await BytesAsync("GET", "/metrics", null, "text/plain").ConfigureAwait(false);
            return Encoding.UTF8.GetString(bytes);
        }

        static string Segment(object value)
        {
            return Uri.EscapeDataString(Convert.ToString(value, System.Globalization.CultureInfo.InvariantCulture));
        }

        async Task<JsonObject> ObjectAsync(string method, string path, JsonObject body)
        {
            var value = await ValueAsync(method, path, body).ConfigureAwait(false);
            var obj = value as JsonObject;
            if (obj == null) throw new PhantomTouchException("transport", method + " " + path + ": expected a JSON object");
            return obj;
        }

        async Task<object> ValueAsync(string method, string path, JsonObject body)
        {
            var answer = await ExchangeAsync(method, path, body, "application/json").ConfigureAwait(false);
            if (answer.Body.Length == 0) return null;
            try { return Json.Parse(answer.Text); }
            catch (JsonException e) { throw new PhantomTouchException("transport", method + " " + path + ": " + e.Message, answer.Status); }
        }

        async Task<byte[]> BytesAsync(string method, string path, JsonObject body, string accept)
        {
            var answer = await ExchangeAsync(method, path, body, accept).ConfigureAwait(false);
            return answer.Body;
        }

        async Task<HttpAnswer> ExchangeAsync(string method, string path, JsonObject body, string accept)
        {
            var headers = new Dictionary<string, string> { { "Accept", accept } };
            if (Token != null) headers["Authorization"] = "Bearer " + Token;
            var answer = await http.SendAsync(method, BaseUrl + path, body == null ? null : Json.Serialize(body), headers)
                                   .ConfigureAwait(false);
            if (answer.Status == 0)
                throw new PhantomTouchException("transport", method + " " + path + ": " + (answer.Error ?? "no answer"));
            if (answer.Status >= 200 && answer.Status < 300) return answer;
            JsonObject error = null;
            try { error = Json.Parse(answer.Text) as JsonObject; }
            catch (JsonException) { }
            if (error != null && error.GetObject("error") != null) throw PhantomTouchException.FromError(error, answer.Status);
            throw new PhantomTouchException("http_error", method + " " + path + ": " + answer.Text, answer.Status);
        }
    }
}
