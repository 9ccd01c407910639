// Where a point on a virtual forearm lands on the armband, in cm.
//
// The forearm is described in its own local space (metres): the points where the
// armband's wrist end (y = 0 cm) and elbow end (y = BandLengthCm) sit, a direction
// "across" the forearm (towards increasing x), and the width across the forearm that the
// band's columns span, centred on the wrist-elbow line. A point is projected onto the
// wrist-elbow line for y and onto the across direction for x; both are clamped to the band.
using System;

namespace PhantomTouch
{
    public sealed class ForearmMapping
    {
        public double[] WristEnd = { 0, 0, 0 };
        public double[] ElbowEnd = { 0, 0, 0.144 };
        public double[] AcrossAxis = { 1, 0, 0 };
        /// <summary>Width across the forearm that maps to x = 0 .. BandWidthCm, metres.</summary>
        public double WidthM = 0.038;
        /// <summary>The armband's extent around (x) and along (y) the forearm, cm; the default
        /// is the paper's band: 2 columns 3.8 cm apart, 4 rows 4.8 cm apart.</summary>
        public double BandWidthCm = 3.8;
        public double BandLengthCm = 14.4;

        /// <summary>Armband coordinates {x_cm, y_cm} of a point in the forearm's local space.</summary>
        public double[] ToArmbandCm(double px, double py, double pz)
        {
            double ax = ElbowEnd[0] - WristEnd[0], ay = ElbowEnd[1] - WristEnd[1], az = ElbowEnd[2] - WristEnd[2];
            double length2 = ax * ax + ay * ay + az * az;
            if (length2 < 1e-12) throw new InvalidOperationException("the wrist and elbow ends coincide");
            double dx = px - WristEnd[0], dy = py - WristEnd[1], dz = pz - WristEnd[2];
            double along = (dx * ax + dy * ay + dz * az) / length2;
            // The across direction, made perpendicular to the forearm's axis.
            double k = (AcrossAxis[0] * ax + AcrossAxis[1] * ay + AcrossAxis[2] * az) / length2;
            double cx = AcrossAxis[0] - k * ax, cy = AcrossAxis[1] - k * ay, cz = AcrossAxis[2] - k * az;
            double norm = Math.Sqrt(cx * cx + cy * cy + cz * cz);
            double across = 0.5;
            if (norm > 1e-9 && WidthM > 0) across = (dx * cx + dy * cy + dz * cz) / norm / WidthM + 0.5;
            return new[] { Clamp01(across) * BandWidthCm, Clamp01(along) * BandLengthCm };
        }

        static double Clamp01(double v) { return v < 0 ? 0 : (v > 1 ? 1 : v); }
    }
}
