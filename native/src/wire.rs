//! The wire of one frame without Python (issue 43, docs/frame_path.md): camdirector.v1's
//! FrameUpdate read from the request's bytes and checked as worker/codec.py's `frame_from_msg`
//! checks it, and the reply's CameraUpdate written as `camera_update_msg(...).SerializeToString()`
//! writes it. Hand-written protobuf (proto/camdirector/v1/director.proto), the few messages a
//! frame needs, read as upb reads them: a field given twice keeps its last value, a message field
//! given twice is merged, a repeated double may come packed or not, a field of an unknown number
//! or of the wrong wire type is skipped. What this reader does not take (a frame's game events and
//! player stats, groups, anything malformed) is answered `None`: the caller hands such a frame to
//! the Python codec, the reference.

/// A protobuf wire type: the low three bits of a field's tag.
const VARINT: u32 = 0;
const I64: u32 = 1;
const LEN: u32 = 2;
const I32: u32 = 5;

/// Doubles per packed object: px, py, pz, qx, qy, qz, qw, sx, sy, sz (codec.PACKED_STRIDE).
pub const STRIDE: usize = 10;
/// A quaternion shorter than this is refused (codec.transform_from_msg, transforms_from_packed).
const MIN_QUATERNION_NORM: f64 = 1e-6;
/// A scale component smaller than this in magnitude is refused (the same functions).
const MIN_SCALE: f64 = 1e-9;

struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn new(buf: &'a [u8]) -> Self {
        Reader { buf, pos: 0 }
    }

    fn done(&self) -> bool {
        self.pos >= self.buf.len()
    }

    /// A varint of up to 10 bytes, the bits past 64 dropped (as upb does).
    fn varint(&mut self) -> Option<u64> {
        let mut value = 0u64;
        for i in 0..10 {
            let byte = *self.buf.get(self.pos)?;
            self.pos += 1;
            value |= u64::from(byte & 0x7f).checked_shl(7 * i).unwrap_or(0);
            if byte & 0x80 == 0 {
                return Some(value);
            }
        }
        None
    }

    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let end = self.pos.checked_add(n)?;
        let bytes = self.buf.get(self.pos..end)?;
        self.pos = end;
        Some(bytes)
    }

    fn double(&mut self) -> Option<f64> {
        let bytes = self.take(8)?;
        Some(f64::from_le_bytes(bytes.try_into().ok()?))
    }

    fn len_delimited(&mut self) -> Option<&'a [u8]> {
        let n = usize::try_from(self.varint()?).ok()?;
        self.take(n)
    }

    /// The next field's (number, wire type); None at a tag upb would refuse.
    fn tag(&mut self) -> Option<(u32, u32)> {
        let tag = u32::try_from(self.varint()?).ok()?;
        let number = tag >> 3;
        (number != 0).then_some((number, tag & 7))
    }

    /// Skips a field of no interest; None for a group (wire types 3 and 4) or a malformed value.
    fn skip(&mut self, wire: u32) -> Option<()> {
        match wire {
            VARINT => self.varint().map(|_| ()),
            I64 => self.take(8).map(|_| ()),
            LEN => self.len_delimited().map(|_| ()),
            I32 => self.take(4).map(|_| ()),
            _ => None,
        }
    }
}

fn utf8(bytes: &[u8]) -> Option<&str> {
    std::str::from_utf8(bytes).ok()
}

/// A Vec3's or Quat's fields 1.. merged into `values` (a field given again replaces the last).
fn merge_doubles<const N: usize>(values: &mut [f64; N], buf: &[u8]) -> Option<()> {
    let mut r = Reader::new(buf);
    while !r.done() {
        let (number, wire) = r.tag()?;
        let index = number as usize - 1;
        if index < N && wire == I64 {
            values[index] = r.double()?;
        } else {
            r.skip(wire)?;
        }
    }
    Some(())
}

/// camdirector.v1.Transform as codec.transform_from_msg reads it: an unset position is the
/// origin; rotation and scale None when unset.
#[derive(Clone, Debug, Default)]
pub struct Transform {
    pub position: [f64; 3],
    pub rotation: Option<[f64; 4]>,
    pub scale: Option<[f64; 3]>,
}

impl Transform {
    fn merge(&mut self, buf: &[u8]) -> Option<()> {
        let mut r = Reader::new(buf);
        while !r.done() {
            match r.tag()? {
                (1, LEN) => merge_doubles(&mut self.position, r.len_delimited()?)?,
                (2, LEN) => {
                    merge_doubles(self.rotation.get_or_insert([0.0; 4]), r.len_delimited()?)?
                }
                (3, LEN) => merge_doubles(self.scale.get_or_insert([0.0; 3]), r.len_delimited()?)?,
                (_, wire) => r.skip(wire)?,
            }
        }
        Some(())
    }
}

/// camdirector.v1.ObjectState.
#[derive(Clone, Debug, Default)]
pub struct ObjectState<'a> {
    pub id: &'a str,
    pub transform: Transform,
}

impl<'a> ObjectState<'a> {
    fn parse(buf: &'a [u8]) -> Option<Self> {
        let mut state = ObjectState::default();
        let mut r = Reader::new(buf);
        while !r.done() {
            match r.tag()? {
                (1, LEN) => state.id = utf8(r.len_delimited()?)?,
                (2, LEN) => state.transform.merge(r.len_delimited()?)?,
                (_, wire) => r.skip(wire)?,
            }
        }
        Some(state)
    }
}

/// camdirector.v1.FrameUpdate without its game input (events, player_stats) and answered_frame,
/// which the session table reads before the codec.
#[derive(Debug, Default)]
pub struct FrameUpdate<'a> {
    pub session_id: &'a str,
    pub frame: u64,
    pub time_s: f64,
    pub states: Vec<ObjectState<'a>>,
    pub packed_ids: Vec<&'a str>,
    pub packed_transforms: Vec<f64>,
}

impl<'a> FrameUpdate<'a> {
    /// The frame, or None when it carries game events or player stats (field 7 or 8, the Python
    /// codec's) or anything this reader does not take (module docstring).
    pub fn parse(buf: &'a [u8]) -> Option<Self> {
        let mut msg = FrameUpdate::default();
        let mut r = Reader::new(buf);
        while !r.done() {
            match r.tag()? {
                (1, LEN) => msg.session_id = utf8(r.len_delimited()?)?,
                (2, VARINT) => msg.frame = r.varint()?,
                (3, I64) => msg.time_s = r.double()?,
                (4, LEN) => msg.states.push(ObjectState::parse(r.len_delimited()?)?),
                (5, LEN) => msg.packed_ids.push(utf8(r.len_delimited()?)?),
                (6, I64) => msg.packed_transforms.push(r.double()?),
                (6, LEN) => {
                    let packed = r.len_delimited()?;
                    if packed.len() % 8 != 0 {
                        return None;
                    }
                    msg.packed_transforms.extend(
                        packed
                            .chunks_exact(8)
                            .map(|b| f64::from_le_bytes(b.try_into().unwrap())),
                    );
                }
                (7 | 8, _) => return None,
                (_, wire) => r.skip(wire)?,
            }
        }
        Some(msg)
    }
}

/// What a session knows of an object id (Session.movable_ids, static_ids).
pub enum Known {
    Movable,
    Static,
    Unknown,
}

/// How a frame is refused: the gRPC status codec.py's invalid, not_found and precondition give.
#[derive(Debug, PartialEq)]
pub enum Status {
    InvalidArgument,
    NotFound,
    FailedPrecondition,
}

#[derive(Debug)]
pub struct Refusal {
    pub status: Status,
    pub message: String,
}

fn invalid(message: String) -> Refusal {
    Refusal {
        status: Status::InvalidArgument,
        message,
    }
}

/// What the checks ask of the session: the frame's ids by index, the states' first, then the
/// packed ones.
pub trait Objects {
    fn known(&self, index: usize) -> Known;
    /// The id as Python's repr() writes it, for the messages.
    fn quoted(&self, index: usize) -> String;
}

/// sqrt(x^2 + y^2 + z^2 + w^2), summed in that order: the same bits on every machine (numpy's
/// norm may differ in the last bit, by its BLAS).
fn norm(q: &[f64]) -> f64 {
    q.iter().fold(0.0, |sum, x| sum + x * x).sqrt()
}

fn finite(values: &[f64]) -> bool {
    values.iter().all(|x| x.is_finite())
}

/// codec.transform_from_msg: the row px, py, pz, qx, qy, qz, qw, sx, sy, sz, the rotation
/// normalised (identity when unset), the scale ones when unset.
fn transform_row(t: &Transform, what: impl Fn() -> String) -> Result<[f64; STRIDE], Refusal> {
    let mut row = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0];
    if !finite(&t.position) {
        return Err(invalid(format!(
            "{}.position has a NaN or infinite component",
            what()
        )));
    }
    row[0..3].copy_from_slice(&t.position);
    if let Some(q) = &t.rotation {
        if !finite(q) {
            return Err(invalid(format!(
                "{}.rotation has a NaN or infinite component",
                what()
            )));
        }
        let n = norm(q);
        if n < MIN_QUATERNION_NORM {
            return Err(invalid(format!(
                "{}.rotation is a zero-length quaternion",
                what()
            )));
        }
        for k in 0..4 {
            row[3 + k] = q[k] / n;
        }
    }
    if let Some(s) = &t.scale {
        if !finite(s) {
            return Err(invalid(format!(
                "{}.scale has a NaN or infinite component",
                what()
            )));
        }
        if s.iter().any(|x| x.abs() < MIN_SCALE) {
            return Err(invalid(format!("{}.scale has a zero component", what())));
        }
        row[7..10].copy_from_slice(s);
    }
    Ok(row)
}

/// codec.frame_from_msg's checks, in its order and with its messages, on a frame without game
/// input: the states' rows (as transform_row) then the packed ones (as transforms_from_packed:
/// every row checked for non-finite values first, then for a zero quaternion, then for a zero
/// scale, each naming the first row that fails).
pub fn checked_rows(
    msg: &FrameUpdate,
    objects: &impl Objects,
) -> Result<Vec<[f64; STRIDE]>, Refusal> {
    if !msg.time_s.is_finite() {
        return Err(invalid("frame time_s is NaN or infinite".to_string()));
    }
    let check = |index: usize| -> Result<(), Refusal> {
        match objects.known(index) {
            Known::Movable => Ok(()),
            Known::Static => Err(Refusal {
                status: Status::FailedPrecondition,
                message: format!(
                    "object {} is static; create it with dynamic=true to move it",
                    objects.quoted(index)
                ),
            }),
            Known::Unknown => Err(Refusal {
                status: Status::NotFound,
                message: format!(
                    "unknown object id {} in frame {}",
                    objects.quoted(index),
                    msg.frame
                ),
            }),
        }
    };
    let mut rows = Vec::with_capacity(msg.states.len() + msg.packed_ids.len());
    for (i, state) in msg.states.iter().enumerate() {
        check(i)?;
        rows.push(transform_row(&state.transform, || {
            format!("state {} transform", objects.quoted(i))
        })?);
    }
    if msg.packed_ids.is_empty() && msg.packed_transforms.is_empty() {
        return Ok(rows);
    }
    let values = &msg.packed_transforms;
    if values.len() != STRIDE * msg.packed_ids.len() {
        return Err(invalid(format!(
            "packed_transforms holds {} values; {STRIDE} per packed id expected",
            values.len()
        )));
    }
    let first = msg.states.len();
    for j in 0..msg.packed_ids.len() {
        check(first + j)?;
    }
    let packed: Vec<&[f64]> = values.chunks_exact(STRIDE).collect();
    let norms: Vec<f64> = packed.iter().map(|row| norm(&row[3..7])).collect();
    let refuse = |j: usize, message: &str| {
        invalid(format!(
            "packed state {} {message}",
            objects.quoted(first + j)
        ))
    };
    if let Some(j) = packed.iter().position(|row| !finite(row)) {
        return Err(refuse(j, "has a NaN or infinite value"));
    }
    if let Some(j) = norms.iter().position(|&n| n < MIN_QUATERNION_NORM) {
        return Err(refuse(j, "rotation is a zero-length quaternion"));
    }
    if let Some(j) = packed
        .iter()
        .position(|row| row[7..10].iter().any(|x| x.abs() < MIN_SCALE))
    {
        return Err(refuse(j, "scale has a zero component"));
    }
    for (row, n) in packed.iter().zip(norms) {
        let mut out = [0.0; STRIDE];
        out.copy_from_slice(row);
        for k in 3..7 {
            out[k] = row[k] / n;
        }
        rows.push(out);
    }
    Ok(rows)
}

/// A protobuf message being written, fields in ascending number (as upb writes them).
pub struct Writer {
    pub buf: Vec<u8>,
}

impl Writer {
    pub fn with_capacity(bytes: usize) -> Self {
        Writer {
            buf: Vec::with_capacity(bytes),
        }
    }

    fn varint(&mut self, mut value: u64) {
        while value >= 0x80 {
            self.buf.push((value as u8) | 0x80);
            value >>= 7;
        }
        self.buf.push(value as u8);
    }

    fn tag(&mut self, number: u32, wire: u32) {
        self.varint(u64::from(number << 3 | wire));
    }

    /// A double field, left out when its bits are zero (proto3; -0.0 is written, as upb does).
    pub fn double(&mut self, number: u32, value: f64) {
        if value.to_bits() != 0 {
            self.double_always(number, value);
        }
    }

    fn double_always(&mut self, number: u32, value: f64) {
        self.tag(number, I64);
        self.buf.extend_from_slice(&value.to_le_bytes());
    }

    /// An unsigned integer field, left out when zero.
    pub fn unsigned(&mut self, number: u32, value: u64) {
        if value != 0 {
            self.tag(number, VARINT);
            self.varint(value);
        }
    }

    pub fn boolean(&mut self, number: u32, value: bool) {
        self.unsigned(number, u64::from(value));
    }

    fn string_always(&mut self, number: u32, value: &str) {
        self.bytes(number, value.as_bytes());
    }

    fn bytes(&mut self, number: u32, value: &[u8]) {
        self.tag(number, LEN);
        self.varint(value.len() as u64);
        self.buf.extend_from_slice(value);
    }

    /// A message field, written even when empty (it is set).
    pub fn message(&mut self, number: u32, write: impl FnOnce(&mut Writer)) {
        let mut inner = Writer::with_capacity(128);
        write(&mut inner);
        self.bytes(number, &inner.buf);
    }

    /// A map<string, double>'s entries, each with its key and value even when empty or zero (as
    /// upb writes them), in the order of the keys' bytes: upb's own order is its hash table's,
    /// which changes from one process to the next.
    pub fn string_double_map(&mut self, number: u32, entries: &mut [(String, f64)]) {
        entries.sort_by(|a, b| a.0.as_bytes().cmp(b.0.as_bytes()));
        for (key, value) in entries.iter() {
            self.message(number, |entry| {
                entry.string_always(1, key);
                entry.double_always(2, *value);
            });
        }
    }
}

/// camera.CameraPose's fields.
pub struct Pose {
    pub position_world: [f64; 3],
    pub rotation_xyzw: [f64; 4],
    pub vertical_fov_deg: f64,
}

/// CameraUpdate.diagnostics as codec.camera_update_msg fills it: theta and phi with the TORIC
/// part, alpha with its torus; always present (it extends `flags`, which sets it).
pub struct Diagnostics {
    pub toric: Option<(f64, f64, Option<f64>)>,
    pub stage_ms: Vec<(String, f64)>,
    pub flags: Vec<String>,
    pub scores: Vec<(String, f64)>,
}

/// The reply to a computed frame without a MATCH part, written in two pieces around compute_ms
/// (field 7), which the session table sets once the frame is done; stale (8) and message (9) are
/// a stale reply's, which the Python codec makes.
pub struct CameraUpdate {
    pub frame: u64,
    pub time_s: f64,
    pub pose: Option<Pose>,
    pub cut: bool,
    pub shot_id: u64,
    pub visibility: f64,
    pub diagnostics: Diagnostics,
}

impl CameraUpdate {
    /// (fields 1-6, fields 10-13): the reply's bytes are the first, compute_ms, the second.
    pub fn pieces(mut self) -> (Vec<u8>, Vec<u8>) {
        let mut head = Writer::with_capacity(128);
        head.unsigned(1, self.frame);
        head.double(2, self.time_s);
        if let Some(pose) = &self.pose {
            head.message(3, |w| {
                let p = &pose.position_world;
                w.message(1, |v| (1..).zip(p).for_each(|(n, x)| v.double(n, *x)));
                let q = &pose.rotation_xyzw;
                w.message(2, |v| (1..).zip(q).for_each(|(n, x)| v.double(n, *x)));
                w.double(3, pose.vertical_fov_deg);
            });
        }
        head.boolean(4, self.cut);
        head.unsigned(5, self.shot_id);
        head.double(6, self.visibility);
        let mut tail = Writer::with_capacity(256);
        let d = &mut self.diagnostics;
        tail.message(10, |w| {
            if let Some((theta, phi, alpha)) = d.toric {
                w.double(1, theta);
                w.double(2, phi);
                if let Some(alpha) = alpha {
                    w.double(3, alpha);
                }
            }
            w.string_double_map(4, &mut d.stage_ms);
            d.flags.iter().for_each(|flag| w.string_always(5, flag));
            w.string_double_map(6, &mut d.scores);
        });
        // 11 shot, 12 candidates and 13 buffering are MATCH's: never set here.
        (head.buf, tail.buf)
    }
}

/// The whole reply: `head`, compute_ms, `tail` (CameraUpdate::pieces).
pub fn reply_bytes(head: &[u8], compute_ms: f64, tail: &[u8]) -> Vec<u8> {
    let mut w = Writer::with_capacity(head.len() + 9 + tail.len());
    w.buf.extend_from_slice(head);
    w.double(7, compute_ms);
    w.buf.extend_from_slice(tail);
    w.buf
}

/// The session_id of a serialized request (field 1, a string, in every request that names a
/// session), read as front/router.py's `session_id_of` reads it: the first field 1 of wire type
/// LEN counts, the fields before it must be well formed and the rest is not read. Ok("") when it
/// has none; Err(()) for bytes that are not fields before it, or a session_id that is not UTF-8.
pub fn session_id(buf: &[u8]) -> Result<&str, ()> {
    let mut r = Reader::new(buf);
    while !r.done() {
        match r.tag().ok_or(())? {
            (1, LEN) => return utf8(r.len_delimited().ok_or(())?).ok_or(()),
            (_, wire) => r.skip(wire).ok_or(())?,
        }
    }
    Ok("")
}
