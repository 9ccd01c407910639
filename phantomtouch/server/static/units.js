// Shared display helpers: channel colours, level scale and number formatting.

// Eight well-separated colours, one per output channel (repeats past eight).
const CHANNEL_COLORS = [
  "#2563eb", "#ea580c", "#16a34a", "#dc2626", "#7c3aed", "#0891b2", "#c026d3", "#a16207",
];

export function channelColor(index) {
  return CHANNEL_COLORS[((index % CHANNEL_COLORS.length) + CHANNEL_COLORS.length)
    % CHANNEL_COLORS.length];
}

// Levels are peak sample values (1 = full scale); a linear scale would hide the quiet
// ones, so they are shown on a dB scale from FLOOR_DBFS to 0 dBFS.
export const FLOOR_DBFS = -60;

export function dbfs(level) {
  return level > 0 ? 20 * Math.log10(level) : -Infinity;
}

export function levelNorm(level) {
  const db = dbfs(level);
  if (!Number.isFinite(db)) return 0;
  return Math.min(1, Math.max(0, (db - FLOOR_DBFS) / -FLOOR_DBFS));
}

export function formatNumber(value, digits = 2) {
  if (value === null || value === undefined || Number.isNaN(Number(value))) return "–";
  return Number(value).toLocaleString("en-US", {
    minimumFractionDigits: digits, maximumFractionDigits: digits,
  });
}
