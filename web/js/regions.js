// A task's regions (collie.tasks Task.to_dict()) as Plotly shapes, shaded as the paper's Fig. 2:
// red undesirable, green neutral, yellow desirable. The background class fills the plot area,
// then each region is painted over it in order (later wins), as the task rule decides.

// bad, neutral, good: collie/class_colours.py (the plots and the labeling UI), held equal by a test
export const CLASS_COLOURS = ["#d62728", "#2ca02c", "#e6b800"];
export const FILL = ["#f9d9d9", "#d9efd9", "#fbefb8"]; // opaque, so a region replaces what is under it
const CIRCLE_STEPS = 96;

const point = ([x, y]) => `${x.toFixed(4)},${y.toFixed(4)}`;
const polygon = (points) => `M${points.map(point).join("L")}Z`;

function circle([cx, cy], r) {
  const points = [];
  for (let i = 0; i < CIRCLE_STEPS; i++) {
    const a = (2 * Math.PI * i) / CIRCLE_STEPS;
    points.push([cx + r * Math.cos(a), cy + r * Math.sin(a)]);
  }
  return polygon(points);
}

// The SVG path of a region within `box` = {x0, x1, y0, y1} (already larger than the view), or
// null when it has no x-y shape (pitch) or no meaning in a 1-D view (`oneD`: only half-planes).
export function regionPath(region, box, oneD) {
  const { x0, x1, y0, y1 } = box;
  const everything = polygon([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]);
  switch (region.kind) {
    case "halfplane_right":
      return polygon([[region.x0, y0], [x1, y0], [x1, y1], [region.x0, y1]]);
    case "halfplane_left":
      return polygon([[x0, y0], [region.x0, y0], [region.x0, y1], [x0, y1]]);
    case "disc":
      return oneD ? null : circle(region.centre, region.radius);
    case "outside_disc":
      return oneD ? null : everything + circle(region.centre, region.radius); // even-odd: a hole
    case "polygon":
      return oneD ? null : polygon(region.vertices);
    case "wedge_north": {
      if (oneD) return null;
      const [ax, ay] = region.apex;
      // tall enough to cover the box wherever it lies (a segment's small box far up the wedge too)
      const reach = Math.max(x1 - x0, y1 - y0, y1 - ay);
      return polygon([[ax, ay], [ax + reach, ay + reach], [ax - reach, ay + reach]]);
    }
    default:
      return null; // pitch_beyond and unknown kinds: nothing to draw in x-y
  }
}

export function regionShapes(task, view, oneD = false) {
  if (!task) return [];
  const w = view.x[1] - view.x[0];
  const h = view.y[1] - view.y[0];
  const box = { x0: view.x[0] - 2 * w, x1: view.x[1] + 2 * w, y0: view.y[0] - 2 * h, y1: view.y[1] + 2 * h };
  const shapes = [{
    type: "rect", xref: "paper", yref: "paper", x0: 0, x1: 1, y0: 0, y1: 1,
    fillcolor: FILL[task.background], line: { width: 0 }, layer: "below",
  }];
  for (const region of task.regions) {
    const path = regionPath(region, box, oneD);
    if (path) {
      shapes.push({
        type: "path", path, xref: "x", yref: "y", fillcolor: FILL[region.desirability],
        fillrule: "evenodd", line: { width: 0 }, layer: "below",
      });
    }
  }
  return shapes;
}

// What the map cannot show, in words (e.g. not_flip's pitch rule), for the note under it.
export function undrawn(task, oneD) {
  if (!task) return [];
  const notes = [];
  for (const r of task.regions) {
    if (r.kind === "pitch_beyond") notes.push(`bad where |pitch| > ${Math.round((r.limit * 180) / Math.PI)}° (not drawn)`);
    else if (oneD && !r.kind.startsWith("halfplane")) notes.push(`${r.kind} not drawn on a 1-D map`);
  }
  return notes;
}
