// Numbers as the page shows them.

// A duration in milliseconds as "420 ms", "9.76 s" or "2 min 05 s": three
// significant figures at most, never a thousands separator inside a unit.
export function formatDuration(ms) {
  if (!Number.isFinite(ms) || ms < 0) return '–';
  if (ms < 1) return `${ms.toFixed(2)} ms`;
  if (ms < 10) return `${ms.toFixed(1)} ms`;
  if (ms < 999.5) return `${Math.round(ms)} ms`;
  const s = ms / 1000;
  if (s < 9.995) return `${s.toFixed(2)} s`;
  if (s < 59.95) return `${s.toFixed(1)} s`;
  const whole = Math.round(s);
  return `${Math.floor(whole / 60)} min ${String(whole % 60).padStart(2, '0')} s`;
}

// A count with the user's thousands separators ("1,234,567").
export function formatCount(n) {
  return Number.isFinite(n) ? Math.round(n).toLocaleString() : '–';
}
