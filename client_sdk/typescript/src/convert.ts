/**
 * Packed transforms and conversions from and to game-engine frames, as the Python SDK's
 * camdirector_client.convert (the same formulas, term for term, so the answers are the same
 * doubles).
 *
 * Our frame (the wire contract's): right-handed, +Y up, metres; a camera looks down its local -Z
 * with +Y up. Quaternions are (x, y, z, w).
 *
 * Unity: left-handed, +Y up, +Z forward, metres.
 *     ours = (x, y, -z); q_ours = (-qx, -qy, qz, qw); scales unchanged. Each map is its own inverse.
 * Unreal: left-handed, +Z up, +X forward, +Y right, centimetres.
 *     ours = (y, z, -x) / 100; q_ours = (-qy, -qz, qx, qw); s_ours = (sy, sz, sx);
 *     back: ue = 100 (-z, x, y), q_ue = (qz, -qx, -qy, qw), s_ue = (sz, sx, sy).
 *
 * Every converter takes one vector (3 numbers) or quaternion (4), or a batch of them flat
 * (3n or 4n numbers, row after row), and returns a new Float64Array of the same length.
 */
import { create } from "@bufbuild/protobuf";
import {
  MeshSchema, QuatSchema, TransformSchema, TriangleMeshSchema, Vec3Schema,
  type CameraPose, type Mesh, type Quat, type Transform, type Vec3,
} from "./gen/camdirector/v1/director_pb.js";
import { DirectorError } from "./errors.js";
import { PACKED_WIDTH, type Packed } from "./wire.js";

type Numbers = ArrayLike<number>;

function rows(values: Numbers, width: number, name: string): Float64Array {
  if (values.length === 0 || values.length % width !== 0) {
    throw new DirectorError("INVALID_ARGUMENT", `${name} must hold ${width} numbers per row, got ${values.length}`);
  }
  return values instanceof Float64Array ? values : Float64Array.from(values as ArrayLike<number>);
}

/** out[i*w + k] = a[i*w + axes[k]] * sign[k] * scale, for each row (the Python SDK's array[..., axes] * sign * scale). */
function permute(values: Numbers, width: number, name: string, axes: readonly number[], sign: readonly number[], mul?: number, div?: number): Float64Array {
  const a = rows(values, width, name);
  const out = new Float64Array(a.length);
  for (let row = 0; row < a.length; row += width) {
    for (let k = 0; k < width; k++) {
      let v = a[row + axes[k]!]! * sign[k]!;
      if (mul !== undefined) v *= mul;
      if (div !== undefined) v /= div;
      out[row + k] = v;
    }
  }
  return out;
}

const XYZ = [0, 1, 2], XYZW = [0, 1, 2, 3];
const UNITY_POSITION_SIGN = [1, 1, -1], UNITY_ROTATION_SIGN = [-1, -1, 1, 1];
const FROM_UNREAL_AXES = [1, 2, 0], FROM_UNREAL_POSITION_SIGN = [1, 1, -1];
const TO_UNREAL_AXES = [2, 0, 1], TO_UNREAL_POSITION_SIGN = [-1, 1, 1];
const FROM_UNREAL_QUAT_AXES = [1, 2, 0, 3], FROM_UNREAL_QUAT_SIGN = [-1, -1, 1, 1];
const TO_UNREAL_QUAT_AXES = [2, 0, 1, 3], TO_UNREAL_QUAT_SIGN = [1, -1, -1, 1];
const ONES3 = [1, 1, 1];
const UNREAL_CM_PER_M = 100;

/** Unity positions or directions (metres) in our frame: (x, y, -z). */
export const fromUnityPosition = (p: Numbers) => permute(p, 3, "position", XYZ, UNITY_POSITION_SIGN);
/** Our positions or directions in Unity's frame: (x, y, -z). */
export const toUnityPosition = (p: Numbers) => permute(p, 3, "position", XYZ, UNITY_POSITION_SIGN);
/** Unity quaternions (x, y, z, w) in our frame: (-x, -y, z, w). */
export const fromUnityRotation = (q: Numbers) => permute(q, 4, "rotation", XYZW, UNITY_ROTATION_SIGN);
/** Our quaternions in Unity's frame: (-x, -y, z, w). */
export const toUnityRotation = (q: Numbers) => permute(q, 4, "rotation", XYZW, UNITY_ROTATION_SIGN);
/** Unity local scales in our frame: unchanged (a copy). */
export const fromUnityScale = (s: Numbers) => Float64Array.from(rows(s, 3, "scale"));
/** Our local scales in Unity's frame: unchanged (a copy). */
export const toUnityScale = (s: Numbers) => Float64Array.from(rows(s, 3, "scale"));

/** Unreal positions in centimetres as ours in metres: (y, z, -x) / 100. */
export const fromUnrealPosition = (p: Numbers) =>
  permute(p, 3, "position", FROM_UNREAL_AXES, FROM_UNREAL_POSITION_SIGN, undefined, UNREAL_CM_PER_M);
/** Our positions in metres as Unreal's in centimetres: 100 (-z, x, y). */
export const toUnrealPosition = (p: Numbers) =>
  permute(p, 3, "position", TO_UNREAL_AXES, TO_UNREAL_POSITION_SIGN, UNREAL_CM_PER_M);
/** Unreal FQuat components (x, y, z, w) in our frame: (-y, -z, x, w). */
export const fromUnrealRotation = (q: Numbers) => permute(q, 4, "rotation", FROM_UNREAL_QUAT_AXES, FROM_UNREAL_QUAT_SIGN);
/** Our quaternions as Unreal FQuat components: (z, -x, -y, w). */
export const toUnrealRotation = (q: Numbers) => permute(q, 4, "rotation", TO_UNREAL_QUAT_AXES, TO_UNREAL_QUAT_SIGN);
/** Unreal local scales (X, Y, Z) in our frame: (sy, sz, sx). */
export const fromUnrealScale = (s: Numbers) => permute(s, 3, "scale", FROM_UNREAL_AXES, ONES3);
/** Our local scales as Unreal's (X, Y, Z): (sz, sx, sy). */
export const toUnrealScale = (s: Numbers) => permute(s, 3, "scale", TO_UNREAL_AXES, ONES3);

/**
 * Row-major 3x3 rotation matrices (9 numbers per quaternion) of quaternions (x, y, z, w),
 * normalised first; a zero quaternion gives the identity.
 */
export function rotationMatrix(q: Numbers): Float64Array {
  const a = rows(q, 4, "rotation");
  const out = new Float64Array((a.length / 4) * 9);
  for (let i = 0, o = 0; i < a.length; i += 4, o += 9) {
    let x = a[i]!, y = a[i + 1]!, z = a[i + 2]!, w = a[i + 3]!;
    const norm = Math.sqrt(x * x + y * y + z * z + w * w);
    if (norm > 0) { x /= norm; y /= norm; z /= norm; w /= norm; } else { x = 0; y = 0; z = 0; w = 1; }
    out[o] = 1 - 2 * (y * y + z * z);
    out[o + 1] = 2 * (x * y - z * w);
    out[o + 2] = 2 * (x * z + y * w);
    out[o + 3] = 2 * (x * y + z * w);
    out[o + 4] = 1 - 2 * (x * x + z * z);
    out[o + 5] = 2 * (y * z - x * w);
    out[o + 6] = 2 * (x * z - y * w);
    out[o + 7] = 2 * (y * z + x * w);
    out[o + 8] = 1 - 2 * (x * x + y * y);
  }
  return out;
}

/** A camera pose in our frame: position (metres), camera-to-world unit quaternion (x, y, z, w), vertical fov. */
export interface Pose {
  position: Float64Array;
  rotation: Float64Array;
  verticalFovDeg: number;
}

/** A Pose from a CameraPose message; an unset or zero rotation is the identity. */
export function poseFromMsg(pose: CameraPose | undefined): Pose {
  const p = pose?.position, r = pose?.rotation;
  const rotation = new Float64Array([r?.x ?? 0, r?.y ?? 0, r?.z ?? 0, r?.w ?? 0]);
  const [x, y, z, w] = rotation as unknown as [number, number, number, number];
  const norm = Math.sqrt(x * x + y * y + z * z + w * w);
  if (norm > 0) for (let k = 0; k < 4; k++) rotation[k]! /= norm;
  else rotation[3] = 1;
  return { position: new Float64Array([p?.x ?? 0, p?.y ?? 0, p?.z ?? 0]), rotation, verticalFovDeg: pose?.verticalFovDeg ?? 0 };
}

function asPose(pose: Pose | CameraPose): Pose {
  return pose.position instanceof Float64Array ? (pose as Pose) : poseFromMsg(pose as CameraPose);
}

/** Position (metres) and rotation (x, y, z, w) of a Unity camera (looks down +Z) showing what `pose` shows;
 * Unity's Camera.fieldOfView is vertical, so pose.verticalFovDeg applies as it is. */
export function cameraPoseToUnity(pose: Pose | CameraPose): { position: Float64Array; rotation: Float64Array } {
  const p = asPose(pose);
  return { position: toUnityPosition(p.position), rotation: toUnityRotation(p.rotation) };
}

/** Position (centimetres) and FQuat (x, y, z, w) of an Unreal camera (looks down +X, +Z up) showing
 * what `pose` shows; Unreal's FieldOfView is horizontal: see horizontalFovDeg. */
export function cameraPoseToUnreal(pose: Pose | CameraPose): { position: Float64Array; rotation: Float64Array } {
  const p = asPose(pose);
  return { position: toUnrealPosition(p.position), rotation: toUnrealRotation(p.rotation) };
}

/** Horizontal field of view (degrees) of a vertical one at aspect = width / height. */
export function horizontalFovDeg(verticalFovDeg: number, aspect: number): number {
  const half = (verticalFovDeg * (Math.PI / 180)) / 2;
  return 2 * Math.atan(Math.tan(half) * aspect) * (180 / Math.PI);
}

/** A Vec3 message. */
export function vec3(v: Numbers): Vec3 {
  if (v.length !== 3) throw new DirectorError("INVALID_ARGUMENT", `a Vec3 needs 3 numbers, got ${v.length}`);
  return create(Vec3Schema, { x: v[0]!, y: v[1]!, z: v[2]! });
}

/** A Quat message (x, y, z, w). */
export function quat(q: Numbers): Quat {
  if (q.length !== 4) throw new DirectorError("INVALID_ARGUMENT", `a Quat needs 4 numbers, got ${q.length}`);
  return create(QuatSchema, { x: q[0]!, y: q[1]!, z: q[2]!, w: q[3]! });
}

/** A Transform; a rotation or scale left out stays unset (identity, (1, 1, 1)). */
export function transformMsg(position: Numbers, rotation?: Numbers, scale?: Numbers): Transform {
  return create(TransformSchema, {
    position: vec3(position), rotation: rotation ? quat(rotation) : undefined, scale: scale ? vec3(scale) : undefined,
  });
}

/** A triangle Mesh from vertices (3n numbers, metres, local frame) and faces (3m vertex indices).
 * flipWinding reverses each triangle (for triangles from Unity or Unreal after converting their vertices). */
export function meshFromArrays(vertices: Numbers, faces: ArrayLike<number>, flipWinding = false): Mesh {
  if (vertices.length % 3 !== 0) throw new DirectorError("INVALID_ARGUMENT", `vertices must be 3n numbers, got ${vertices.length}`);
  if (faces.length % 3 !== 0) throw new DirectorError("INVALID_ARGUMENT", `faces must be 3m indices, got ${faces.length}`);
  const n = vertices.length / 3;
  const indices = Uint32Array.from(faces as ArrayLike<number>);
  for (let i = 0; i < indices.length; i++) {
    const f = faces[i]!;
    if (!Number.isInteger(f) || f < 0 || f >= n) throw new DirectorError("INVALID_ARGUMENT", `faces must index vertices in [0, ${n}), got ${f}`);
  }
  if (flipWinding) for (let i = 0; i < indices.length; i += 3) { const b = indices[i + 1]!; indices[i + 1] = indices[i + 2]!; indices[i + 2] = b; }
  const v32 = Float32Array.from(vertices as ArrayLike<number>);
  return create(MeshSchema, { source: { case: "triangles", value: create(TriangleMeshSchema, { vertices: Array.from(v32), indices: Array.from(indices) }) } });
}

/**
 * The bulk form of object states for FrameUpdate.packed_ids / packed_transforms (Session.frame's
 * `packed`): positions 3n, rotations 4n (x, y, z, w), scales 3n or none ((1, 1, 1)); a Float64Array
 * of 10 doubles per id (px, py, pz, qx, qy, qz, qw, sx, sy, sz).
 */
export function packStates(ids: readonly string[], positions: Numbers, rotations: Numbers, scales?: Numbers): Packed & { transforms: Float64Array } {
  const n = ids.length;
  if (!ids.every((id) => typeof id === "string")) throw new DirectorError("INVALID_ARGUMENT", "ids must be strings");
  if (positions.length !== 3 * n) throw new DirectorError("INVALID_ARGUMENT", `positions must be ${3 * n} numbers for ${n} ids, got ${positions.length}`);
  if (rotations.length !== 4 * n) throw new DirectorError("INVALID_ARGUMENT", `rotations must be ${4 * n} numbers for ${n} ids, got ${rotations.length}`);
  if (scales && scales.length !== 3 * n) throw new DirectorError("INVALID_ARGUMENT", `scales must be ${3 * n} numbers for ${n} ids, got ${scales.length}`);
  const out = new Float64Array(PACKED_WIDTH * n);
  for (let i = 0; i < n; i++) {
    const o = PACKED_WIDTH * i;
    out[o] = positions[3 * i]!; out[o + 1] = positions[3 * i + 1]!; out[o + 2] = positions[3 * i + 2]!;
    out[o + 3] = rotations[4 * i]!; out[o + 4] = rotations[4 * i + 1]!; out[o + 5] = rotations[4 * i + 2]!; out[o + 6] = rotations[4 * i + 3]!;
    if (scales) { out[o + 7] = scales[3 * i]!; out[o + 8] = scales[3 * i + 1]!; out[o + 9] = scales[3 * i + 2]!; }
    else { out[o + 7] = 1; out[o + 8] = 1; out[o + 9] = 1; }
  }
  return { ids: [...ids], transforms: out };
}

/** Inverse of packStates: ids, positions (3n), rotations (4n), scales (3n). */
export function unpackStates(ids: readonly string[], transforms: Numbers) {
  const n = ids.length;
  if (transforms.length !== PACKED_WIDTH * n) throw new DirectorError("INVALID_ARGUMENT", `${n} ids need ${PACKED_WIDTH * n} doubles, got ${transforms.length}`);
  const positions = new Float64Array(3 * n), rotations = new Float64Array(4 * n), scales = new Float64Array(3 * n);
  for (let i = 0; i < n; i++) {
    const o = PACKED_WIDTH * i;
    for (let k = 0; k < 3; k++) { positions[3 * i + k] = transforms[o + k]!; scales[3 * i + k] = transforms[o + 7 + k]!; }
    for (let k = 0; k < 4; k++) rotations[4 * i + k] = transforms[o + 3 + k]!;
  }
  return { ids: [...ids], positions, rotations, scales };
}
