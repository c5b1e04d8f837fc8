// The framing error (docs/protocol.md): how far the framed points land from where the style puts
// them, normalised screen units (the frame is [-1, 1]; null where the rig does not measure it).
// Above FRAMING_LOST the framing has failed: a point is a quarter of the frame's height from its
// place. That puts a long or medium tracks shot's framed ends (placed at y -0.8 and 0.8) 0.3 out
// of the frame, and a Toric target (at x -1/3 or 1/3 by default) drifting outward at x 0.83, by
// the frame's side edge. The timeline's strip and the top view's marks both show it.
export const FRAMING_LOST = 0.5;
export const FRAMING_STRIP_MAX = 1.0;   // the strip's framing band spans 0 to a frame's half-height; above is clipped
export const FRAMING_COLOUR = "#e040fb";   // its line in the strip and the top view's marks: no other mark's colour
