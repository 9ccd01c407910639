// The WebSocket session with the service, off the caller's thread.
//
// Down/Move/Up/Play... never block: they put a message where a background send loop
// picks it up. Moves go to a latest-wins slot per contact (a burst of moves within one
// frame costs one message, the newest); every other message goes to a FIFO queue. The
// send loop sends the queue first and then the slot, at most MoveRateHz times a second,
// and sends a ping whenever nothing went out for a quarter of the server's watchdog_s.
//
// State machine: Idle -> Connecting -> Connected -> (socket lost) -> Connecting ... ->
// Closed (Dispose). Each (re)connection says hello, waits for welcome, then puts every
// contact that is still down back at its newest position and re-subscribes. Reconnect
// attempts back off exponentially (ReconnectInitialMs doubling up to ReconnectMaxMs).
//
// Contact lane: when the welcome offers one (docs/lane.md) and UseLane is true, the moves
// taken from the latest-wins slots go as UDP datagrams to the service's host (ContactLane),
// which takes them without waiting behind its HTTP work; everything else, the moves of a
// contact whose down the server has not confirmed yet (each down carries an id for that),
// and the move an Up sends first (so that it arrives before the up), stays on the socket. No lane offered,
// or the lane given up (port unreachable, key refused): moves go over the socket. The lane
// closes with the connection; each reconnection opens its own.
//
// Events are raised on a background thread; a Unity component hands them to the main
// thread (see PhantomTouchManager).
using System;
using System.Collections.Concurrent;
using System.Collections.Generic;
using System.Diagnostics;
using System.IO;
using System.Net.WebSockets;
using System.Text;
using System.Threading;
using System.Threading.Tasks;

namespace PhantomTouch
{
    public enum SessionState { Idle, Connecting, Connected, Closed }

    public sealed class WebSocketSession : IDisposable
    {
        sealed class ActiveContact
        {
            public double X, Y, Intensity = double.NaN;
            // The id of the contact's newest down, and whether the server confirmed it: a
            // move goes over the lane only then (it must not overtake its down).
            public string DownId;
            public bool Confirmed;
        }

        readonly Uri uri;
        readonly string token;
        readonly string clientName;
        readonly object gate = new object();
        readonly Queue<string> queue = new Queue<string>();
        readonly Dictionary<string, JsonObject> moveSlot = new Dictionary<string, JsonObject>();
        readonly Dictionary<string, ActiveContact> contacts = new Dictionary<string, ActiveContact>();
        readonly ConcurrentDictionary<string, TaskCompletionSource<JsonObject>> pending =
            new ConcurrentDictionary<string, TaskCompletionSource<JsonObject>>();
        readonly SemaphoreSlim wake = new SemaphoreSlim(0, int.MaxValue);
        readonly CancellationTokenSource life = new CancellationTokenSource();
        readonly Stopwatch clock = Stopwatch.StartNew();
        double subscribedHz;
        int nextId;
        long lastSendMs, lastReceiveMs, nextMoveMs;
        double clockOffsetS = double.NaN;
        Task loop;

        /// <summary>Most moves sent per second (one per frame at 90 Hz by default).</summary>
        public double MoveRateHz = 90;
        /// <summary>Longest silence before a ping, ms; 0: a quarter of the server's watchdog_s.</summary>
        public int PingIntervalMs = 0;
        public int ReconnectInitialMs = 100;
        public int ReconnectMaxMs = 5000;
        /// <summary>How long a connection attempt and a request may take, ms.</summary>
        public int TimeoutMs = 5000;
        /// <summary>Send moves over the service's contact lane when its welcome offers one
        /// (set before Start); false: every message goes over the WebSocket.</summary>
        public bool UseLane = true;

        public SessionState State { get; private set; }
        public bool IsConnected { get { return State == SessionState.Connected; } }
        /// <summary>How many times the session has reconnected after losing the socket.</summary>
        public int Reconnects { get; private set; }
        /// <summary>The newest welcome (protocol, server_time_s, watchdog_s, device).</summary>
        public JsonObject Welcome { get; private set; }
        /// <summary>The contact lane of the current connection; null when none is offered,
        /// UseLane is false, or the session is not connected.</summary>
        public ContactLane Lane { get; private set; }

        /// <summary>true when (re)connected, false when the socket is lost.</summary>
        public event Action<bool> ConnectionChanged;
        /// <summary>A "state" message (after Subscribe).</summary>
        public event Action<JsonObject> StateReceived;
        /// <summary>A "released" message: the server released these contacts of this session
        /// (reason "watchdog": the session went silent; "stop": a global stop).</summary>
        public event Action<JsonObject> Released;
        /// <summary>An "error" that answers no pending request (e.g. a bad move).</summary>
        public event Action<PhantomTouchException> ErrorReceived;
        /// <summary>A problem of the transport itself (connection failures), for logging.</summary>
        public event Action<string> Log;

        public WebSocketSession(Uri uri, string token = null, string clientName = "phantomtouch-csharp")
        {
            this.uri = uri;
            this.token = token;
            this.clientName = clientName;
            State = SessionState.Idle;
        }

        /// <summary>Starts connecting in the background; the session reconnects by itself.</summary>
        public void Start()
        {
            lock (gate)
            {
                if (State != SessionState.Idle) throw new InvalidOperationException("expected an idle session, got " + State);
                State = SessionState.Connecting;
            }
            loop = Task.Run(() => RunAsync(life.Token));
        }

        /// <summary>Waits until the session is connected (true) or the time is up (false).</summary>
        public bool WaitConnected(int timeoutMs)
        {
            var deadline = clock.ElapsedMilliseconds + timeoutMs;
            while (!IsConnected && clock.ElapsedMilliseconds < deadline && State != SessionState.Closed)
                Thread.Sleep(10);
            return IsConnected;
        }

        /// <summary>The server clock now, estimated from the newest pong (NaN before one).</summary>
        public double ServerTimeS
        {
            get { return clockOffsetS + clock.Elapsed.TotalSeconds; }
        }

        /// <summary>A contact touches down. While disconnected it is remembered and put
        /// down when the session is back.</summary>
        public void Down(string contact, double xCm, double yCm, double intensity = double.NaN)
        {
            lock (gate)
            {
                var active = new ActiveContact { X = xCm, Y = yCm, Intensity = intensity };
                contacts[contact] = active;
                moveSlot.Remove(contact);
                if (IsConnected) queue.Enqueue(DownMessage(contact, active));
            }
            Wake();
        }

        string DownMessage(string contact, ActiveContact active)
        {
            active.DownId = "cs-down-" + Interlocked.Increment(ref nextId);
            active.Confirmed = false;
            var down = Messages.Down(contact, active.X, active.Y, active.Intensity);
            down["id"] = active.DownId;
            return Json.Serialize(down);
        }

        /// <summary>The contact's newest position: replaces a move not sent yet (latest wins).</summary>
        public void Move(string contact, double xCm, double yCm, double intensity = double.NaN)
        {
            lock (gate)
            {
                ActiveContact active;
                if (!contacts.TryGetValue(contact, out active)) return;
                active.X = xCm;
                active.Y = yCm;
                if (!double.IsNaN(intensity)) active.Intensity = intensity;
                if (IsConnected) moveSlot[contact] = Messages.Move(contact, xCm, yCm, intensity);
            }
            Wake();
        }

        /// <summary>Lift-off, after the contact's newest move.</summary>
        public void Up(string contact)
        {
            lock (gate)
            {
                if (!contacts.Remove(contact)) return;
                JsonObject move;
                if (moveSlot.TryGetValue(contact, out move))
                {
                    queue.Enqueue(Json.Serialize(move));
                    moveSlot.Remove(contact);
                }
                if (IsConnected) queue.Enqueue(Json.Serialize(Messages.Up(contact)));
            }
            Wake();
        }

        /// <summary>The contacts held down, with their newest positions (x_cm, y_cm).</summary>
        public Dictionary<string, double[]> ActiveContacts()
        {
            lock (gate)
            {
                var copy = new Dictionary<string, double[]>();
                foreach (var c in contacts) copy[c.Key] = new[] { c.Value.X, c.Value.Y };
                return copy;
            }
        }

        /// <summary>Sends a message with a fresh id; the task ends with the "ok" (or "pong")
        /// reply, or fails with the PhantomTouchException of an "error" reply.</summary>
        public Task<JsonObject> RequestAsync(JsonObject message)
        {
            var id = "cs-" + Interlocked.Increment(ref nextId);
            var reply = new TaskCompletionSource<JsonObject>(TaskCreationOptions.RunContinuationsAsynchronously);
            var copy = new JsonObject();
            foreach (var field in message) copy[field.Key] = field.Value;
            copy["id"] = id;
            lock (gate)
            {
                if (!IsConnected)
                {
                    reply.SetException(new PhantomTouchException("transport", "not connected to " + uri));
                    return reply.Task;
                }
                pending[id] = reply;
                queue.Enqueue(Json.Serialize(copy));
            }
            Wake();
            var timeout = new CancellationTokenSource(TimeoutMs);
            timeout.Token.Register(() =>
            {
                TaskCompletionSource<JsonObject> waiting;
                if (pending.TryRemove(id, out waiting))
                    waiting.TrySetException(new PhantomTouchException("timeout", "no reply to " + message.GetString("type") + " in " + TimeoutMs + " ms"));
            });
            reply.Task.ContinueWith(t => timeout.Dispose());
            return reply.Task;
        }

        /// <summary>Schedules a touch (as POST /touch); the reply's "result" is the job.</summary>
        public async Task<JsonObject> PlayAsync(TouchRequest request)
        {
            var reply = await RequestAsync(Messages.Play(request)).ConfigureAwait(false);
            return reply.GetObject("result") ?? new JsonObject();
        }

        /// <summary>Stops one job, or everything of every client when jobId is null.</summary>
        public Task<JsonObject> StopAsync(object jobId = null)
        {
            var m = new JsonObject().With("type", "stop");
            if (jobId != null) m["job_id"] = jobId;
            return RequestAsync(m);
        }

        /// <summary>Asks for "state" messages at rateHz (0 stops them); kept across reconnects.</summary>
        public async Task SubscribeAsync(double rateHz)
        {
            await RequestAsync(Messages.Subscribe(rateHz)).ConfigureAwait(false);
            subscribedHz = rateHz;
        }

        /// <summary>Pings the server; answers its clock (server_time_s).</summary>
        public async Task<double> PingAsync()
        {
            var reply = await RequestAsync(Messages.Ping()).ConfigureAwait(false);
            return reply.GetNumber("server_time_s");
        }

        public void Dispose()
        {
            lock (gate)
            {
                if (State == SessionState.Closed) return;
                State = SessionState.Closed;
            }
            life.Cancel();
            Wake();
            // Cancelling aborts the socket at once; the wait is bounded so that a Unity
            // OnDisable never holds the main thread for long.
            if (loop != null)
            {
                try { loop.Wait(1000); } catch (AggregateException) { }
            }
            CloseLane();
            FailPending(new PhantomTouchException("transport", "the session was closed"));
        }

        void CloseLane()
        {
            var lane = Lane;
            Lane = null;
            if (lane != null) lane.Dispose();
        }

        void Wake()
        {
            if (wake.CurrentCount == 0) wake.Release();
        }

        void Say(string what)
        {
            var log = Log;
            if (log != null) log(what);
        }

        async Task RunAsync(CancellationToken stop)
        {
            int attempt = 0;
            bool everConnected = false;
            while (!stop.IsCancellationRequested)
            {
                using (var ws = new ClientWebSocket())
                {
                    bool connected = false;
                    try
                    {
                        await OpenAsync(ws, stop).ConfigureAwait(false);
                        connected = true;
                        attempt = 0;
                        if (everConnected) Reconnects++;
                        everConnected = true;
                        if (UseLane) Lane = ContactLane.Open(Welcome, uri.Host, Dispatch, Say);
                        Restore();
                        Raise(ConnectionChanged, true);
                        using (var linked = CancellationTokenSource.CreateLinkedTokenSource(stop))
                        {
                            var receiving = ReceiveLoopAsync(ws, linked.Token);
                            var sending = SendLoopAsync(ws, linked.Token);
                            var first = await Task.WhenAny(receiving, sending).ConfigureAwait(false);
                            linked.Cancel();
                            try { await Task.WhenAll(receiving, sending).ConfigureAwait(false); }
                            catch (Exception) { }
                            if (first.IsFaulted && !stop.IsCancellationRequested)
                                Say("connection lost: " + first.Exception.GetBaseException().Message);
                        }
                    }
                    catch (Exception e)
                    {
                        if (!stop.IsCancellationRequested) Say("cannot connect to " + uri + ": " + e.GetBaseException().Message);
                    }
                    CloseLane();
                    lock (gate)
                    {
                        if (State != SessionState.Closed) State = SessionState.Connecting;
                        queue.Clear();
                        moveSlot.Clear();
                    }
                    FailPending(new PhantomTouchException("transport", "the connection to " + uri + " was lost"));
                    if (connected) Raise(ConnectionChanged, false);
                    if (ws.State == WebSocketState.Open)
                    {
                        try
                        {
                            using (var bye = new CancellationTokenSource(1000))
                                await ws.CloseAsync(WebSocketCloseStatus.NormalClosure, "bye", bye.Token).ConfigureAwait(false);
                        }
                        catch (Exception) { }
                    }
                }
                if (stop.IsCancellationRequested) break;
                int delay = (int)Math.Min(ReconnectMaxMs, ReconnectInitialMs * Math.Pow(2, Math.Min(attempt, 16)));
                attempt++;
                try { await Task.Delay(delay, stop).ConfigureAwait(false); }
                catch (OperationCanceledException) { break; }
            }
        }

        async Task OpenAsync(ClientWebSocket ws, CancellationToken stop)
        {
            if (!string.IsNullOrEmpty(token)) ws.Options.SetRequestHeader("Authorization", "Bearer " + token);
            ws.Options.KeepAliveInterval = TimeSpan.FromSeconds(5);
            using (var timeout = CancellationTokenSource.CreateLinkedTokenSource(stop))
            {
                timeout.CancelAfter(TimeoutMs);
                await ws.ConnectAsync(uri, timeout.Token).ConfigureAwait(false);
                await SendTextAsync(ws, Json.Serialize(Messages.Hello(clientName)), timeout.Token).ConfigureAwait(false);
                lastSendMs = clock.ElapsedMilliseconds;
                while (true)
                {
                    var message = await ReceiveMessageAsync(ws, timeout.Token).ConfigureAwait(false);
                    if (message == null)
                    {
                        // 1008 before the welcome: the token is missing or wrong.
                        var policy = ws.CloseStatus == WebSocketCloseStatus.PolicyViolation;
                        throw new PhantomTouchException(policy ? "unauthorized" : "transport",
                            "closed before welcome: " + ws.CloseStatus + " " + ws.CloseStatusDescription);
                    }
                    var type = message.GetString("type");
                    if (type == "welcome")
                    {
                        Welcome = message;
                        clockOffsetS = message.GetNumber("server_time_s") - clock.Elapsed.TotalSeconds;
                        return;
                    }
                    if (type == "error") throw PhantomTouchException.FromError(message, 0);
                }
            }
        }

        void Restore()
        {
            lock (gate)
            {
                queue.Clear();
                moveSlot.Clear();
                foreach (var c in contacts)
                    queue.Enqueue(DownMessage(c.Key, c.Value));
                if (subscribedHz > 0) queue.Enqueue(Json.Serialize(Messages.Subscribe(subscribedHz)));
                lastReceiveMs = clock.ElapsedMilliseconds;
                if (State != SessionState.Closed) State = SessionState.Connected;
            }
            Wake();
        }

        int PingIntervalNow()
        {
            if (PingIntervalMs > 0) return PingIntervalMs;
            var welcome = Welcome;
            double watchdogS = welcome != null ? welcome.GetNumber("watchdog_s", 2.0) : 2.0;
            return Math.Max(50, (int)(watchdogS * 1000 / 4));
        }

        async Task SendLoopAsync(ClientWebSocket ws, CancellationToken stop)
        {
            var batch = new List<string>();
            // The moves of this round, each with whether it may take the lane (its down is
            // confirmed), and those that do.
            var moves = new List<KeyValuePair<JsonObject, bool>>();
            var laneMoves = new List<JsonObject>();
            while (!stop.IsCancellationRequested)
            {
                int pingMs = PingIntervalNow();
                long now = clock.ElapsedMilliseconds;
                // A server that answered nothing (not even a pong) for two ping rounds past
                // the watchdog is gone: drop the socket and reconnect.
                if (now - Interlocked.Read(ref lastReceiveMs) > 4 * pingMs + TimeoutMs)
                    throw new PhantomTouchException("timeout", "the server stopped answering");
                long wait = lastSendMs + pingMs - now;
                lock (gate)
                {
                    if (moveSlot.Count > 0) wait = Math.Min(wait, nextMoveMs - now);
                    if (queue.Count > 0) wait = 0;
                }
                if (wait > 0) await wake.WaitAsync((int)Math.Min(wait, pingMs), stop).ConfigureAwait(false);
                now = clock.ElapsedMilliseconds;
                batch.Clear();
                moves.Clear();
                lock (gate)
                {
                    while (queue.Count > 0) batch.Add(queue.Dequeue());
                    if (moveSlot.Count > 0 && now >= nextMoveMs)
                    {
                        foreach (var slot in moveSlot)
                        {
                            ActiveContact active;
                            var confirmed = contacts.TryGetValue(slot.Key, out active) && active.Confirmed;
                            moves.Add(new KeyValuePair<JsonObject, bool>(slot.Value, confirmed));
                        }
                        moveSlot.Clear();
                        nextMoveMs = now + (long)(1000.0 / Math.Max(1.0, MoveRateHz));
                    }
                }
                var lane = Lane;
                laneMoves.Clear();
                foreach (var move in moves)
                {
                    if (lane != null && lane.Usable && move.Value) laneMoves.Add(move.Key);
                    else batch.Add(Json.Serialize(move.Key));
                }
                if (batch.Count == 0 && now - lastSendMs >= pingMs) batch.Add(Json.Serialize(Messages.Ping()));
                foreach (var text in batch)
                {
                    await SendTextAsync(ws, text, stop).ConfigureAwait(false);
                    lastSendMs = clock.ElapsedMilliseconds;
                }
                foreach (var move in laneMoves)
                {
                    if (!lane.TrySend(move))
                        await SendTextAsync(ws, Json.Serialize(move), stop).ConfigureAwait(false);
                }
            }
        }

        static Task SendTextAsync(ClientWebSocket ws, string text, CancellationToken stop)
        {
            var bytes = Encoding.UTF8.GetBytes(text);
            return ws.SendAsync(new ArraySegment<byte>(bytes), WebSocketMessageType.Text, true, stop);
        }

        static async Task<JsonObject> ReceiveMessageAsync(ClientWebSocket ws, CancellationToken stop)
        {
            var buffer = new byte[8192];
            using (var message = new MemoryStream())
            {
                while (true)
                {
                    var result = await ws.ReceiveAsync(new ArraySegment<byte>(buffer), stop).ConfigureAwait(false);
                    if (result.MessageType == WebSocketMessageType.Close) return null;
                    message.Write(buffer, 0, result.Count);
                    if (!result.EndOfMessage) continue;
                    if (result.MessageType != WebSocketMessageType.Text) { message.SetLength(0); continue; }
                    return Json.ParseObject(Encoding.UTF8.GetString(message.GetBuffer(), 0, (int)message.Length));
                }
            }
        }

        async Task ReceiveLoopAsync(ClientWebSocket ws, CancellationToken stop)
        {
            while (!stop.IsCancellationRequested)
            {
                var message = await ReceiveMessageAsync(ws, stop).ConfigureAwait(false);
                if (message == null) throw new PhantomTouchException("transport", "the server closed the connection");
                Interlocked.Exchange(ref lastReceiveMs, clock.ElapsedMilliseconds);
                Dispatch(message);
            }
        }

        void Dispatch(JsonObject message)
        {
            var type = message.GetString("type");
            var id = message.GetString("id");
            TaskCompletionSource<JsonObject> waiting;
            if (id != null && pending.TryRemove(id, out waiting))
            {
                if (type == "error") waiting.TrySetException(PhantomTouchException.FromError(message, 0));
                else waiting.TrySetResult(message);
                if (type == "pong") clockOffsetS = message.GetNumber("server_time_s") - clock.Elapsed.TotalSeconds;
                return;
            }
            switch (type)
            {
                case "ok":
                    if (id == null) break;
                    lock (gate)
                    {
                        foreach (var c in contacts.Values)
                            if (c.DownId == id) c.Confirmed = true;
                    }
                    break;
                case "pong":
                    clockOffsetS = message.GetNumber("server_time_s") - clock.Elapsed.TotalSeconds;
                    break;
                case "state":
                    Raise(StateReceived, message);
                    break;
                case "released":
                    var released = message.GetArray("contacts");
                    if (released != null)
                    {
                        lock (gate)
                        {
                            foreach (var c in released)
                            {
                                var name = c as string;
                                if (name == null) continue;
                                contacts.Remove(name);
                                moveSlot.Remove(name);
                            }
                        }
                    }
                    Raise(Released, message);
                    break;
                case "error":
                    Raise(ErrorReceived, PhantomTouchException.FromError(message, 0));
                    break;
            }
        }

        void FailPending(PhantomTouchException error)
        {
            foreach (var id in pending.Keys)
            {
                TaskCompletionSource<JsonObject> waiting;
                if (pending.TryRemove(id, out waiting)) waiting.TrySetException(error);
            }
        }

        void Raise<T>(Action<T> handler, T value)
        {
            if (handler == null) return;
            try { handler(value); }
            catch (Exception e) { Say("an event handler failed: " + e); }
        }
    }
}
