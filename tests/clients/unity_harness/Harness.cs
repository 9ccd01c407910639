// Console harness: drives the live service with the same PhantomTouchClient class the
// Unity scripts use. tests/clients/test_client_unity.py runs it and checks the server side.
//
//   harness.exe selftest                 JSON and forearm mapping, no server
//   harness.exe rest URL                 every REST route; prints "JOB <id>" for the touch
//   harness.exe stroke URL CONTACT       a WebSocket down, moves (faster than frames), up
//   harness.exe lane URL CONTACT on|off  a down, moves and an up with the contact lane on
//                                        or off, then a move the lane refuses
//   harness.exe reconnect URL CONTACT    holds a contact across a server restart, driven
//                                        by lines on stdin (see the test)
//
// Every line it prints is "KEY value"; it ends with "DONE" and exit code 0 on success.
using System;
using System.Collections.Generic;
using System.Globalization;
using System.Text;
using System.Threading;

namespace PhantomTouch.Harness
{
    public static class Program
    {
        public static int Main(string[] args)
        {
            // A comma decimal separator must not leak into the protocol.
            Thread.CurrentThread.CurrentCulture = new CultureInfo("de-DE");
            try
            {
                switch (args.Length > 0 ? args[0] : "")
                {
                    case "selftest": SelfTest(); break;
                    case "rest": Rest(args[1]); break;
                    case "stroke": Stroke(args[1], args[2]); break;
                    case "reconnect": Reconnect(args[1], args[2]); break;
                    case "lane": Lane(args[1], args[2], args[3] == "on"); break;
                    default:
                        Console.Error.WriteLine("usage: harness.exe selftest | rest URL | stroke URL CONTACT | reconnect URL CONTACT");
                        return 2;
                }
                Say("DONE", "");
                return 0;
            }
            catch (Exception e)
            {
                Console.Error.WriteLine("FAILED " + e);
                return 1;
            }
        }

        static void Say(string key, object value)
        {
            Console.WriteLine(key + " " + Convert.ToString(value, CultureInfo.InvariantCulture));
            Console.Out.Flush();
        }

        static void Check(bool condition, string what)
        {
            if (!condition) throw new Exception("check failed: " + what);
        }

        static PhantomTouchClient NewClient(string url)
        {
            return new PhantomTouchClient(url, new HttpClientTransport());
        }

        static void SelfTest()
        {
            var message = Messages.Move("finger", 1.5, 12.25);
            Say("JSON", Json.Serialize(message));
            var back = Json.ParseObject("{\"a\": [1, 2.5e1, -0.5], \"s\": \"x\\\"y\\u00e9\", \"t\": true, \"n\": null}");
            Check(back.GetArray("a").Count == 3 && (double)back.GetArray("a")[1] == 25.0, "numbers parse");
            Check(back.GetString("s") == "x\"y\u00e9", "string escapes parse");
            Check(Json.Serialize(back.GetString("s")) == "\"x\\\"y\u00e9\"", "strings round-trip");

            var map = new ForearmMapping();
            var wrist = map.ToArmbandCm(0, 0, 0);
            var elbow = map.ToArmbandCm(0, 0, 0.144);
            var edge = map.ToArmbandCm(0.019, 0, 0.072);
            var beyond = map.ToArmbandCm(-1, 0, 1);
            Say("MAP_WRIST", Pair(wrist));
            Say("MAP_ELBOW", Pair(elbow));
            Say("MAP_EDGE", Pair(edge));
            Say("MAP_BEYOND", Pair(beyond));
            var tap = TouchRequest.Tap(1.9, 7.2, 1.7).StartInMs(20);
            Say("TAP", tap);
        }

        static string Pair(double[] cm)
        {
            return cm[0].ToString("R", CultureInfo.InvariantCulture) + "," + cm[1].ToString("R", CultureInfo.InvariantCulture);
        }

        static void Rest(string url)
        {
            var client = NewClient(url);
            Check(client.HealthAsync().Result.GetString("status") == "ok", "health");
            Say("HEALTH", "ok");
            var clock = client.ClockAsync().Result;
            Say("CLOCK", clock.GetNumber("server_time_s"));
            Say("DEVICE", Json.Serialize(client.DeviceAsync().Result));
            var presets = (List<object>)client.PresetsAsync().Result;
            Say("PRESETS", presets.Count);

            var job = client.TouchAsync(TouchRequest.Tap(1.9, 7.2, 0.5).StartInMs(20)).Result;
            Say("JOB", job.GetString("job_id"));
            var preset = client.TouchAsync(TouchRequest.Preset("vr/stroke")).Result;
            Say("PRESET_JOB", preset.GetString("job_id"));
            Say("JOB_STATE", client.JobAsync(preset["job_id"]).Result.GetString("state"));
            Say("CANCELLED", client.CancelJobAsync(preset["job_id"]).Result.GetString("state"));

            var wav = client.RenderWavAsync(TouchRequest.Preset("vr/tap")).Result;
            Say("WAV", Encoding.ASCII.GetString(wav, 0, 4) + Encoding.ASCII.GetString(wav, 8, 4));
            var plan = client.RenderPlanAsync(TouchRequest.Preset("vr/tap")).Result;
            Say("PLAN_POINTS", plan.GetObject("curves").GetArray("times_s").Count);

            var pattern = Json.ParseObject(
                "{\"path\": {\"kind\": \"polyline\", \"points_cm\": [[1.9, 12], [1.9, 2.4]]}, \"speed_cm_s\": 20}");
            client.PutPatternAsync("unity-harness", pattern).Wait();
            Say("STORED", client.GetPatternAsync("unity-harness").Result.GetNumber("speed_cm_s"));
            Say("PATTERNS", Json.Serialize(client.PatternsAsync().Result));
            Say("PATTERN_JOB", client.PlayPatternAsync("unity-harness", 10).Result.GetString("job_id"));
            Say("STORED_JOB", client.TouchAsync(TouchRequest.Stored("unity-harness")).Result.GetNumber("speed_cm_s"));
            client.DeletePatternAsync("unity-harness").Wait();
            try
            {
                client.GetPatternAsync("unity-harness").Wait();
                throw new Exception("a deleted pattern was found");
            }
            catch (AggregateException e)
            {
                var refused = (PhantomTouchException)e.GetBaseException();
                Say("DELETED", refused.Code + " " + refused.Status);
            }
            try
            {
                client.TouchAsync(TouchRequest.Preset("vr/tap", new JsonObject().With("speed_cm_s", -1))).Wait();
                throw new Exception("a negative speed was accepted");
            }
            catch (AggregateException e)
            {
                var refused = (PhantomTouchException)e.GetBaseException();
                Say("REFUSED", refused.Code + " " + refused.Status);
            }
            Say("METRICS_LINES", client.MetricsAsync().Result.Split('\n').Length);
            client.StopAsync().Wait();
            Say("STOPPED", "ok");
        }

        static WebSocketSession Connect(PhantomTouchClient client)
        {
            var session = client.Connect("unity-harness");
            session.Log += line => Console.Error.WriteLine("LOG " + line);
            Check(session.WaitConnected(10000), "connected to " + client.WebSocketUri);
            Say("WELCOME", session.Welcome.GetNumber("watchdog_s"));
            return session;
        }

        static void Stroke(string url, string contact)
        {
            var client = NewClient(url);
            var session = Connect(client);
            Say("PING", session.PingAsync().Result);
            client.Down(contact, 1.9, 2.0, 0.5);
            Thread.Sleep(100);
            // 400 positions in ~0.8 s, more often than a frame: the session sends the newest
            // at most MoveRateHz times a second.
            var started = DateTime.UtcNow;
            for (int i = 1; i <= 400; i++)
            {
                client.Move(contact, 1.9, 2.0 + i * 0.025);
                Thread.Sleep(2);
            }
            Say("MOVED_S", (DateTime.UtcNow - started).TotalSeconds);
            Thread.Sleep(200);
            var job = session.PlayAsync(TouchRequest.Preset("vr/tap")).Result;
            Say("WS_JOB", job.GetString("job_id"));
            try
            {
                session.RequestAsync(new JsonObject().With("type", "no-such-type")).Wait();
                throw new Exception("an unknown type was accepted");
            }
            catch (AggregateException e)
            {
                Say("WS_REFUSED", ((PhantomTouchException)e.GetBaseException()).Code);
            }
            client.Up(contact);
            Thread.Sleep(200);
            client.Dispose();
        }

        static void Lane(string url, string contact, bool useLane)
        {
            var client = NewClient(url);
            var session = client.Connect("unity-lane", useLane);
            session.MoveRateHz = 200;
            var refusals = new System.Collections.Concurrent.ConcurrentQueue<PhantomTouchException>();
            session.ErrorReceived += refusals.Enqueue;
            Check(session.WaitConnected(10000), "connected to " + client.WebSocketUri);
            var offer = session.Welcome.GetObject("lane");
            Say("OFFERED", offer != null ? offer.GetNumber("port").ToString(CultureInfo.InvariantCulture) : "none");
            var lane = session.Lane;
            Say("LANE", lane != null ? lane.Address.ToString() : "none");
            client.Down(contact, 1.9, 2.0, 0.5);
            // The pong comes after the down's ok: the down is confirmed, so its moves may
            // take the lane (before that they go over the socket, behind the down).
            session.PingAsync().Wait();
            // One move every 20 ms (slower than the 200 Hz frames): each is sent.
            for (int i = 1; i <= 20; i++)
            {
                Thread.Sleep(20);
                client.Move(contact, 1.9, 2.0 + i * 0.5);
            }
            Thread.Sleep(300);
            Say("LANE_SENT", lane != null ? lane.MovesSent : 0);
            client.Move(contact, 1.9, 5000.0);   // far off the armband: refused
            var deadline = DateTime.UtcNow.AddSeconds(10);
            while (refusals.IsEmpty && DateTime.UtcNow < deadline) Thread.Sleep(10);
            PhantomTouchException refused;
            Check(refusals.TryDequeue(out refused), "the refusal of a move off the armband");
            Say("REFUSED", refused.Code + " " + refused.Message);
            Say("PING", session.PingAsync().Result);
            client.Up(contact);
            Thread.Sleep(200);
            client.Dispose();
            Say("CLOSED", lane != null ? (!lane.Usable).ToString() : "none");
        }

        static string Expect(string line)
        {
            var got = Console.ReadLine();
            if (got != line) throw new Exception("expected '" + line + "' on stdin, got '" + got + "'");
            return got;
        }

        static void Reconnect(string url, string contact)
        {
            var client = NewClient(url);
            var session = Connect(client);
            bool lost = false;
            session.ConnectionChanged += up => { if (!up) lost = true; };
            client.Down(contact, 1.9, 3.0);
            Say("DOWN", "1.9,3");
            Expect("stopped");
            var deadline = DateTime.UtcNow.AddSeconds(10);
            while (!lost && DateTime.UtcNow < deadline) Thread.Sleep(10);
            Check(lost, "the session noticed the server is gone");
            client.Move(contact, 1.9, 6.0);   // while the server is down: restored on return
            Say("LOST", "moved to 1.9,6");
            Expect("started");
            deadline = DateTime.UtcNow.AddSeconds(20);
            while (!(session.Reconnects >= 1 && session.IsConnected) && DateTime.UtcNow < deadline) Thread.Sleep(10);
            Check(session.Reconnects >= 1 && session.IsConnected, "reconnected");
            Say("RECONNECTED", session.Reconnects);
            Expect("move");
            client.Move(contact, 1.9, 9.0);
            Say("MOVED", "1.9,9");
            Expect("up");
            client.Up(contact);
            Thread.Sleep(200);
            Say("UP", contact);
            client.Dispose();
        }
    }
}
