// The contact lane (the service's docs/lane.md): a live contact's move as one UDP datagram.
//
// A service may offer a lane in its welcome ("lane": {"port", "key"}): a move sent as a UDP
// datagram to that port on the service's host is handed to the engine by a thread of its
// own, without waiting behind the HTTP work of the service's event loop. A ContactLane is
// one WebSocket connection's use of it: a UdpClient connected to the service's host, each
// move sent with the connection's key, and a receive loop that hands the lane's answers (a
// refusal is the "error" message of /ws; "ok" answers a move with an id) to the session.
//
// The lane is given up, and moves go over /ws again, when the host answers that nothing
// listens on the port (ICMP "port unreachable", a SocketException on the connected socket)
// or when the lane refuses the key (the connection closed, or the lane was closed for going
// over the message rate).
using System;
using System.Net;
using System.Net.Sockets;
using System.Text;
using System.Threading;
using System.Threading.Tasks;

namespace PhantomTouch
{
    public sealed class ContactLane : IDisposable
    {
        readonly UdpClient udp;
        readonly string key;
        readonly Action<JsonObject> answered;
        readonly Action<string> log;
        string gaveUp;
        int movesSent;

        /// <summary>The address the moves go to.</summary>
        public IPEndPoint Address { get; private set; }
        /// <summary>How many moves went over the lane.</summary>
        public int MovesSent { get { return Volatile.Read(ref movesSent); } }
        /// <summary>Why the lane is no longer used; null while it is.</summary>
        public string GaveUp { get { return Volatile.Read(ref gaveUp); } }
        /// <summary>True while moves go over the lane.</summary>
        public bool Usable { get { return GaveUp == null; } }

        ContactLane(UdpClient udp, IPEndPoint address, string key, Action<JsonObject> answered, Action<string> log)
        {
            this.udp = udp;
            Address = address;
            this.key = key;
            this.answered = answered;
            this.log = log;
            Task.Run(ReceiveLoopAsync);
        }

        /// <summary>The lane a welcome offers on the service's host, or null when the welcome
        /// offers none or no UDP socket reaches the host. Runs on the session's thread;
        /// answered is called on the lane's receive thread.</summary>
        public static ContactLane Open(JsonObject welcome, string host, Action<JsonObject> answered, Action<string> log)
        {
            var offer = welcome != null ? welcome.GetObject("lane") : null;
            if (offer == null) return null;
            var port = offer.GetNumber("port", 0);
            var key = offer.GetString("key");
            if (!(port >= 1 && port <= 65535) || string.IsNullOrEmpty(key)) return null;
            UdpClient udp = null;
            try
            {
                var address = new IPEndPoint(HostAddress(host), (int)port);
                udp = new UdpClient(address.AddressFamily);
                udp.Connect(address);
                return new ContactLane(udp, address, key, answered, log);
            }
            catch (Exception e) when (e is SocketException || e is ArgumentException)
            {
                if (udp != null) udp.Close();
                log("the lane at " + host + " port " + port + " cannot be reached (" + e.Message + "); moves go over /ws");
                return null;
            }
        }

        static IPAddress HostAddress(string host)
        {
            IPAddress literal;
            if (IPAddress.TryParse(host.Trim('[', ']'), out literal)) return literal;
            var addresses = Dns.GetHostAddresses(host);
            foreach (var address in addresses)
                if (address.AddressFamily == AddressFamily.InterNetwork) return address;
            if (addresses.Length == 0) throw new SocketException((int)SocketError.HostNotFound);
            return addresses[0];
        }

        /// <summary>Sends a move message (Messages.Move) over the lane; false (nothing sent)
        /// once the lane is given up. Runs on the session's send thread.</summary>
        public bool TrySend(JsonObject move)
        {
            if (!Usable) return false;
            var datagram = new JsonObject();
            foreach (var field in move) datagram[field.Key] = field.Value;
            datagram["key"] = key;
            var bytes = Encoding.UTF8.GetBytes(Json.Serialize(datagram));
            try
            {
                udp.Send(bytes, bytes.Length);
            }
            catch (Exception e) when (e is SocketException || e is ObjectDisposedException)
            {
                GiveUp("the lane's host refused its datagrams: " + e.Message);
                return false;
            }
            Interlocked.Increment(ref movesSent);
            return true;
        }

        async Task ReceiveLoopAsync()
        {
            while (Usable)
            {
                UdpReceiveResult result;
                try
                {
                    result = await udp.ReceiveAsync().ConfigureAwait(false);
                }
                catch (Exception e) when (e is SocketException || e is ObjectDisposedException)
                {
                    GiveUp("the lane's host refused its datagrams: " + e.Message);
                    return;
                }
                JsonObject message;
                try
                {
                    message = Json.ParseObject(Encoding.UTF8.GetString(result.Buffer));
                }
                catch (JsonException)
                {
                    log("ignored a lane answer that is not a JSON object");
                    continue;
                }
                if (message.GetString("type") == "error" && NamesKey(message))
                    GiveUp("the lane refused the key: " + message.GetString("message"));
                answered(message);
            }
        }

        static bool NamesKey(JsonObject error)
        {
            var fields = error.GetArray("fields");
            if (fields == null) return false;
            foreach (var field in fields)
            {
                var named = field as JsonObject;
                if (named != null && named.GetString("field") == "key") return true;
            }
            return false;
        }

        void GiveUp(string reason)
        {
            if (Interlocked.CompareExchange(ref gaveUp, reason, null) == null && reason != "closed")
                log("moves go over /ws again: " + reason);
        }

        /// <summary>Closes the socket (the connection ended); moves go over /ws from now on.
        /// Any thread.</summary>
        public void Dispose()
        {
            GiveUp("closed");
            udp.Close();
        }
    }
}
