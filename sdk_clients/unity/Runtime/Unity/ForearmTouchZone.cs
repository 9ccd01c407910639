// Put this on the avatar's forearm, next to a trigger collider that covers the skin under
// the armband. Fingertips (small colliders with a Rigidbody, on the layers in "touchers")
// that enter the trigger touch down at their place on the armband, move with it every
// physics step (the newest position is sent once per frame), and lift off on exit.
//
// The forearm is described in this object's local space: where the band's wrist end
// (y = 0 cm) and elbow end (y = 14.4 cm) are, which local direction points "across"
// the forearm towards increasing x, and how wide (m) the band's two columns spread.
using System.Collections.Generic;
using UnityEngine;

namespace PhantomTouch
{
    [RequireComponent(typeof(Collider))]
    public class ForearmTouchZone : MonoBehaviour
    {
        [Header("Forearm, in this object's local space (m)")]
        [Tooltip("Where the armband's wrist end (y = 0 cm) sits")]
        public Vector3 wristEnd = new Vector3(0f, 0f, 0f);
        [Tooltip("Where the armband's elbow end (y = band length) sits")]
        public Vector3 elbowEnd = new Vector3(0f, 0f, 0.144f);
        [Tooltip("Local direction across the forearm, towards increasing x")]
        public Vector3 acrossAxis = Vector3.right;
        [Tooltip("Width across the forearm that the band's x range covers, centred on the wrist-elbow line (m)")]
        public float widthM = 0.038f;

        [Header("Armband (cm)")]
        public float bandWidthCm = 3.8f;
        public float bandLengthCm = 14.4f;

        [Header("Contacts")]
        public PhantomTouchManager manager;
        [Tooltip("Layers of the colliders that touch (fingertips)")]
        public LayerMask touchers = ~0;
        [Tooltip("If set, only colliders with this tag touch")]
        public string requiredTag = "";
        [Range(0f, 1f)]
        public float intensity = 0.6f;
        [Tooltip("Contact ids are this prefix plus the toucher's instance id")]
        public string contactPrefix = "forearm";

        readonly Dictionary<Collider, string> active = new Dictionary<Collider, string>();
        readonly ForearmMapping mapping = new ForearmMapping();

        void Reset()
        {
            GetComponent<Collider>().isTrigger = true;
        }

        /// <summary>Armband coordinates (x_cm, y_cm) of a point in world space.</summary>
        public Vector2 ToArmbandCm(Vector3 worldPoint)
        {
            mapping.WristEnd = new double[] { wristEnd.x, wristEnd.y, wristEnd.z };
            mapping.ElbowEnd = new double[] { elbowEnd.x, elbowEnd.y, elbowEnd.z };
            mapping.AcrossAxis = new double[] { acrossAxis.x, acrossAxis.y, acrossAxis.z };
            mapping.WidthM = widthM;
            mapping.BandWidthCm = bandWidthCm;
            mapping.BandLengthCm = bandLengthCm;
            var local = transform.InverseTransformPoint(worldPoint);
            var cm = mapping.ToArmbandCm(local.x, local.y, local.z);
            return new Vector2((float)cm[0], (float)cm[1]);
        }

        PhantomTouchClient Client()
        {
            var m = manager != null ? manager : PhantomTouchManager.Instance;
            return m != null && m.Client != null && m.Client.Session != null ? m.Client : null;
        }

        bool Accepts(Collider other)
        {
            if ((touchers.value & (1 << other.gameObject.layer)) == 0) return false;
            return string.IsNullOrEmpty(requiredTag) || other.CompareTag(requiredTag);
        }

        void OnTriggerEnter(Collider other)
        {
            var client = Client();
            if (client == null || !Accepts(other) || active.ContainsKey(other)) return;
            var id = contactPrefix + "-" + other.GetInstanceID();
            var cm = ToArmbandCm(other.bounds.center);
            active[other] = id;
            client.Down(id, cm.x, cm.y, intensity);
        }

        void OnTriggerStay(Collider other)
        {
            string id;
            var client = Client();
            if (client == null || !active.TryGetValue(other, out id)) return;
            var cm = ToArmbandCm(other.bounds.center);
            client.Move(id, cm.x, cm.y);
        }

        void OnTriggerExit(Collider other)
        {
            string id;
            if (!active.TryGetValue(other, out id)) return;
            active.Remove(other);
            var client = Client();
            if (client != null) client.Up(id);
        }

        void OnDisable()
        {
            var client = Client();
            foreach (var id in active.Values)
                if (client != null) client.Up(id);
            active.Clear();
        }

        void OnDrawGizmosSelected()
        {
            Gizmos.color = Color.cyan;
            var wrist = transform.TransformPoint(wristEnd);
            var elbow = transform.TransformPoint(elbowEnd);
            Gizmos.DrawLine(wrist, elbow);
            Gizmos.DrawWireSphere(wrist, widthM / 2);
            Gizmos.color = Color.magenta;
            Gizmos.DrawWireSphere(elbow, widthM / 2);
        }
    }
}
