// The localisation check's arithmetic (docs/wearer.md): where the phantoms are played, and
// how far from there the wearer felt them. Pure: no page, no requests.

// Phantom positions of the check: the centre of each triangle of the layout.
export function checkPoints(device) {
  return device.triangles.map((triangle) => {
    const corners = triangle.map((index) => device.actuators[index]);
    return [
      corners.reduce((sum, a) => sum + a.x_cm, 0) / 3,
      corners.reduce((sum, a) => sum + a.y_cm, 0) / 3,
    ];
  });
}

// Mean error and bias (felt minus intended), cm, of one run's rows {intended, felt}.
export function localisationSummary(rows) {
  const n = rows.length || 1;
  const mean = (f) => rows.reduce((sum, row) => sum + f(row), 0) / n;
  return {
    errorCm: mean((r) => Math.hypot(r.felt[0] - r.intended[0], r.felt[1] - r.intended[1])),
    biasXCm: mean((r) => r.felt[0] - r.intended[0]),
    biasYCm: mean((r) => r.felt[1] - r.intended[1]),
  };
}

export function localisationCsv(runs) {
  const lines = ["run,wearer,intended_x_cm,intended_y_cm,felt_x_cm,felt_y_cm,error_cm"];
  runs.forEach((run, index) => {
    for (const row of run.rows) {
      const error = Math.hypot(row.felt[0] - row.intended[0], row.felt[1] - row.intended[1]);
      const values = [index + 1, run.wearer, ...row.intended, ...row.felt, error];
      lines.push(values.map((v) => (typeof v === "number" ? v.toFixed(4) : v)).join(","));
    }
  });
  return `${lines.join("\n")}\n`;
}
