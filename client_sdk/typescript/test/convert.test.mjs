// Conversions equal the Python SDK's (camdirector_client.convert) on the same random poses: the
// axis maps, scales, packing, rotation matrices and poses to the double; the horizontal field of
// view within 4 ulp (V8's tan/atan and glibc's may round the last bit apart).
import assert from "node:assert/strict";
import { test } from "node:test";
import * as cd from "../dist/index.js";
import { readData } from "./helpers.mjs";

const data = readData();
const ex = data.expected;
const same = (actual, expected, what) => assert.deepStrictEqual(Array.from(actual), expected, what);

test("Unity and Unreal positions, rotations and scales, both ways", () => {
  for (const name of ["fromUnityPosition", "toUnityPosition", "fromUnrealPosition", "toUnrealPosition"]) {
    same(cd[name](new Float64Array(data.positions)), ex[name], name);
    same(cd[name](data.positions), ex[name], `${name} from an Array`);
  }
  for (const name of ["fromUnityRotation", "toUnityRotation", "fromUnrealRotation", "toUnrealRotation"]) {
    same(cd[name](data.rotations), ex[name], name);
  }
  for (const name of ["fromUnityScale", "toUnityScale", "fromUnrealScale", "toUnrealScale"]) same(cd[name](data.scales), ex[name], name);
  // one vector alone, and the round trips
  same(cd.toUnrealPosition(data.positions.slice(0, 3)), ex.toUnrealPosition.slice(0, 3), "one vector");
  const back = cd.fromUnrealRotation(cd.toUnrealRotation(data.rotations));
  same(back, data.rotations, "Unreal rotation round trip");
});

test("rotation matrices, poses and camera poses for Unity and Unreal", () => {
  same(cd.rotationMatrix(data.rawRotations), ex.rotationMatrix, "rotationMatrix");
  data.fovs.forEach((fov, i) => {
    const msg = cd.create(cd.pb.CameraPoseSchema, {
      position: { x: data.positions[3 * i], y: data.positions[3 * i + 1], z: data.positions[3 * i + 2] },
      rotation: { x: data.rawRotations[4 * i], y: data.rawRotations[4 * i + 1], z: data.rawRotations[4 * i + 2], w: data.rawRotations[4 * i + 3] },
      verticalFovDeg: fov,
    });
    const pose = cd.poseFromMsg(msg);
    assert.deepStrictEqual([...pose.position, ...pose.rotation, pose.verticalFovDeg], ex.poseFromMsg[i]);
    const unity = cd.cameraPoseToUnity(msg), unreal = cd.cameraPoseToUnreal(pose);
    assert.deepStrictEqual([...unity.position, ...unity.rotation], ex.cameraPoseToUnity[i]);
    assert.deepStrictEqual([...unreal.position, ...unreal.rotation], ex.cameraPoseToUnreal[i]);
  });
});

test("packStates, and horizontalFovDeg within 4 ulp", () => {
  const ids = data.fovs.map((_, i) => `p${i}`);
  same(cd.packStates(ids, data.positions, data.rotations, data.scales).transforms, ex.packStates, "packStates");
  const unpacked = cd.unpackStates(ids, ex.packStates);
  same(unpacked.positions, data.positions, "unpackStates");
  let worst = 0;
  data.fovs.forEach((fov, i) => {
    const mine = cd.horizontalFovDeg(fov, data.aspects[i]), theirs = ex.horizontalFovDeg[i];
    const ulp = Math.abs(mine - theirs) / (Number.EPSILON * Math.abs(theirs));
    worst = Math.max(worst, ulp);
  });
  assert.ok(worst <= 4, `horizontalFovDeg differs by ${worst} ulp`);
});

test("bad shapes are refused with INVALID_ARGUMENT", () => {
  for (const call of [() => cd.toUnityPosition([1, 2]), () => cd.fromUnrealRotation([1, 2, 3]),
    () => cd.packStates(["a"], [1, 2, 3], [0, 0, 0]), () => cd.meshFromArrays([0, 0, 0], [0, 0, 1])]) {
    assert.throws(call, (e) => e instanceof cd.DirectorError && e.code === "INVALID_ARGUMENT");
  }
});
