// Sample: moves its object back and forth between two local points, so that the sample
// scene's fingertip strokes the forearm without a headset. Replace it by a fingertip that
// follows a tracked hand (see the package README: hand-tracking colliders).
using UnityEngine;

namespace PhantomTouch.Samples
{
    public class StrokeDriver : MonoBehaviour
    {
        [Tooltip("Start of the stroke, in the parent's local space (m)")]
        public Vector3 from = new Vector3(0f, 0.025f, 0.144f);
        [Tooltip("End of the stroke, in the parent's local space (m)")]
        public Vector3 to = new Vector3(0f, 0.025f, 0f);
        [Tooltip("Time for one way (s)")]
        public float strokeS = 2f;

        void FixedUpdate()
        {
            var t = Mathf.PingPong(Time.time / Mathf.Max(strokeS, 0.01f), 1f);
            transform.localPosition = Vector3.Lerp(from, to, t);
        }
    }
}
