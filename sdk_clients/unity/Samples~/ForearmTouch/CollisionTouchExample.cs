// Example: a tap on the armband wherever something hits the forearm.
//
// Put it on the forearm object with a (non-trigger) collider and a ForearmTouchZone
// (used only for its mapping to armband cm). Each collision calls POST /touch with a short
// 150 Hz tap at the contact point; the harder the hit, the stronger the tap.
using UnityEngine;

namespace PhantomTouch.Samples
{
    public class CollisionTouchExample : MonoBehaviour
    {
        public PhantomTouchManager manager;
        public ForearmTouchZone zone;
        [Tooltip("Impact speed that gives full intensity (m/s)")]
        public float fullIntensitySpeedMS = 2f;
        [Tooltip("Weakest tap, so that a gentle contact is still felt (0-1)")]
        [Range(0f, 1f)]
        public float minIntensity = 0.2f;
        [Tooltip("Shortest time between two taps (s)")]
        public float minIntervalS = 0.05f;

        float lastTapS = float.NegativeInfinity;

        void Start()
        {
            if (zone == null) zone = GetComponent<ForearmTouchZone>();
            if (manager == null) manager = PhantomTouchManager.Instance;
        }

        void OnCollisionEnter(Collision collision)
        {
            if (manager == null || zone == null || collision.contactCount == 0) return;
            if (Time.time - lastTapS < minIntervalS) return;
            lastTapS = Time.time;
            var cm = zone.ToArmbandCm(collision.GetContact(0).point);
            var strength = Mathf.Clamp01(collision.relativeVelocity.magnitude / fullIntensitySpeedMS);
            manager.Touch(TouchRequest.Tap(cm.x, cm.y, Mathf.Max(minIntensity, strength)));
        }
    }
}
