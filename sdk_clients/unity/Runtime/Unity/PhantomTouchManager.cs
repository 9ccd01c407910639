// The scene's connection to the phantomtouch service. Add it once (e.g. on an empty
// "PhantomTouch" object); ForearmTouchZone and your own scripts find it as
// PhantomTouchManager.Instance.
//
// REST goes through UnityWebRequest on the main thread; the WebSocket session runs on
// background threads (send loop, receive loop, ping, reconnect), so a frame never waits
// for the network. Session events are handed to the main thread and raised from Update.
using System;
using System.Collections.Concurrent;
using System.Threading.Tasks;
using UnityEngine;

namespace PhantomTouch
{
    [DefaultExecutionOrder(-100)]
    public class PhantomTouchManager : MonoBehaviour
    {
        [Tooltip("The service, e.g. http://127.0.0.1:8000")]
        public string serverUrl = "http://127.0.0.1:8000";
        [Tooltip("The service token; needed when the service listens off loopback")]
        public string token = "";
        [Tooltip("Shown by the service in its logs")]
        public string clientName = "unity";
        [Tooltip("Open the WebSocket for live contacts when enabled")]
        public bool connectOnEnable = true;
        [Tooltip("Most contact moves sent per second (one per frame at 90 Hz)")]
        [Range(10f, 240f)]
        public float moveRateHz = 90f;
        [Tooltip("Send moves over the service's contact lane (UDP) when it offers one")]
        public bool useContactLane = true;
        [Tooltip("Ask the service for state messages (levels, contacts) at this rate; 0: none")]
        [Range(0f, 120f)]
        public float stateRateHz = 0f;
        public bool logConnection = true;

        public static PhantomTouchManager Instance { get; private set; }
        public PhantomTouchClient Client { get; private set; }
        public bool IsConnected { get { return Client != null && Client.Session != null && Client.Session.IsConnected; } }

        /// <summary>Raised on the main thread: true when (re)connected, false when lost.</summary>
        public event Action<bool> ConnectionChanged;
        /// <summary>Raised on the main thread for each "state" message (see stateRateHz).</summary>
        public event Action<JsonObject> StateReceived;

        readonly ConcurrentQueue<Action> mainThread = new ConcurrentQueue<Action>();
        bool subscribed;

        void Awake()
        {
            if (Instance != null && Instance != this)
                Debug.LogWarning("PhantomTouch: more than one PhantomTouchManager; the newest is Instance");
            Instance = this;
            Client = new PhantomTouchClient(serverUrl, new UnityWebRequestTransport(), token);
        }

        void OnEnable()
        {
            if (connectOnEnable) Connect();
        }

        void OnDisable()
        {
            subscribed = false;
            if (Client != null) Client.Disconnect();
        }

        void OnDestroy()
        {
            if (Instance == this) Instance = null;
        }

        /// <summary>Opens the WebSocket session (it reconnects by itself).</summary>
        public void Connect()
        {
            if (Client.Session != null) return;
            var session = Client.Connect(clientName, useContactLane);
            session.MoveRateHz = moveRateHz;
            session.ConnectionChanged += up => mainThread.Enqueue(() => OnConnection(up));
            session.StateReceived += state => mainThread.Enqueue(() => { if (StateReceived != null) StateReceived(state); });
            session.Released += released => mainThread.Enqueue(() => Debug.LogWarning("PhantomTouch: the service released " + Json.Serialize(released.GetArray("contacts")) + " (" + released.GetString("reason") + ")"));
            session.ErrorReceived += error => mainThread.Enqueue(() => Debug.LogWarning("PhantomTouch: " + error.Message));
            if (logConnection) session.Log += line => mainThread.Enqueue(() => Debug.Log("PhantomTouch: " + line));
        }

        void OnConnection(bool up)
        {
            if (logConnection) Debug.Log("PhantomTouch: " + (up ? "connected to " : "lost ") + serverUrl);
            if (up && stateRateHz > 0 && !subscribed && Client.Session != null)
            {
                subscribed = true;
                Report(Client.Session.SubscribeAsync(stateRateHz), "subscribe");
            }
            if (ConnectionChanged != null) ConnectionChanged(up);
        }

        void Update()
        {
            Action action;
            while (mainThread.TryDequeue(out action)) action();
        }

        /// <summary>POST /touch without waiting; a refusal is logged.</summary>
        public void Touch(TouchRequest request)
        {
            Report(Client.TouchAsync(request), "touch");
        }

        /// <summary>POST /stop: everything off, every client.</summary>
        public void StopAll()
        {
            Report(Client.StopAsync(), "stop");
        }

        static async void Report(Task task, string what)
        {
            try { await task; }
            catch (Exception e) { Debug.LogWarning("PhantomTouch: " + what + " failed: " + e.Message); }
        }
    }
}
