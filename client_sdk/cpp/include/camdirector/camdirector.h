/* camdirector C SDK: an automated cinematographer for game engines, over gRPC.
 *
 * A plain C interface (an opaque handle, plain structs, status codes) so that any engine or
 * language can bind it; camdirector.hpp is a thin C++ wrapper over it. The wire contract is
 * proto/camdirector/v1/director.proto and docs/protocol.md; docs/engines.md shows how to use
 * this from Unreal, Unity, Godot or a custom engine.
 *
 * Frame of reference (the wire's): right-handed, +Y up, metres, seconds. Quaternions are
 * (x, y, z, w). A camera looks down its local -Z with +Y up (glTF). The cd_*_unity / cd_*_unreal
 * functions below convert from and to the engines' frames.
 *
 * Threads. One cd_client holds one gRPC channel, one session and one I/O thread of its own,
 * started by cd_client_create. Functions are of two kinds:
 *   - GAME THREAD, NON-BLOCKING: cd_frame_submit, cd_pose_poll, cd_event_poll, cd_client_stats,
 *     cd_session_id, cd_session_slot and the conversions. They never wait on the network (at most
 *     on a short critical section that copies a few hundred bytes) and never allocate memory.
 *     They may be called from any one thread at a time (normally the game thread).
 *   - BLOCKING, WITH A DEADLINE: cd_session_open*, cd_session_update_style, cd_session_take_shot,
 *     cd_session_flush, cd_session_close and cd_client_destroy. Each waits for the server for at
 *     most its timeout_s (a value <= 0 means 10 s). Call them at load time, or from a worker thread.
 *
 * Reconnection. After a dropped connection, a stream ended UNAVAILABLE or a server that went away,
 * the I/O thread opens a new stream on the same session id (the server keeps the session for its
 * resume window, 60 s by default): CD_EVENT_DISCONNECTED, then CD_EVENT_RESUMED. A server with
 * checkpoints (the default) restores the session on that stream, exactly as it was, when the
 * worker process holding it died (the broken stream is the one UNAVAILABLE) or when the server
 * was restarted on the same data directory: the session goes on under the same id. If the server
 * no longer knows the session (NOT_FOUND: the window passed, or a server without checkpoints
 * restarted), or answers UNAVAILABLE on every new stream for over a second over a working
 * connection while it does create sessions (a server without checkpoints lost the session's
 * worker), the I/O thread creates the session again from the request it keeps (with the latest
 * style), with a new id: CD_EVENT_RECREATED. A recreated session starts over: the rig's state, a
 * held TakeShot and the recording are not carried over. Frames submitted meanwhile wait in the
 * bounded queue, which drops the oldest.
 *
 * Retries (issue 40). Every wait before trying again (a stream reopened, a session recreated) is
 * drawn with equal jitter from a cap that starts at cd_config.initial_backoff_s (0.1 s) and doubles
 * up to reconnect_max_s (0.5 s). A session that has had no answer for retry_window_s (30 s) since
 * its first failure ends: CD_EVENT_SESSION_FAILED with CD_UNAVAILABLE. A frame left unanswered for
 * frame_timeout_s (3 s) counts as a hung node: the stream is reopened (a balancer sends it to a
 * live node). A new stream on the same session first sends again the frames the broken one left
 * unanswered (the server answers a frame it already took with its first answer, marked stale), so
 * no object transform is lost with them. Every frame says the newest frame answered
 * (FrameUpdate.answered_frame); a session restored from a checkpoint that fell behind answers
 * DATA_LOSS "resend from K", and the I/O thread sends its kept frames from K again (their answers
 * do not replace the newer pose); a K older than the resend_history_frames kept ends the session:
 * CD_EVENT_SESSION_FAILED with CD_DATA_LOSS.
 *
 * Routing. Every gRPC call of a session carries the metadata header x-camdirector-route: a random
 * key (32 lowercase hex characters, 128 bits from std::random_device) that cd_session_open picks
 * and that CreateSession, every frame stream, UpdateStyle, TakeShot, CloseSession (cd_session_close
 * and cd_client_destroy's) and a recreation all send. A balancer in front of several servers
 * (docs/scaling.md) sends the calls with one key to one server by a consistent hash, and the
 * session to another that restores it when that one is lost. Each cd_session_open picks a new key.
 *
 * Keys and TLS (docs/security.md). A server with authentication on (the default) wants an API key
 * (`camdirector keys create --role engine`) on every call: cd_config.key, else the CAMDIRECTOR_KEY
 * environment variable, goes as the metadata "authorization: Bearer KEY" on every call of the
 * client, the frame streams included. Without a valid key the server answers CD_UNAUTHENTICATED;
 * with a key whose role may not make the call, CD_PERMISSION_DENIED. A key refused while a
 * session streams (revoked meanwhile) ends the session: CD_EVENT_SESSION_FAILED with that status,
 * never a reconnection (another stream would be refused the same). The SDK copies the key and
 * never prints it nor puts it in a message. An address "grpcs://HOST:PORT" connects over TLS,
 * checking the server's certificate against cd_config.ca_file (a studio's own CA) or else the
 * system's roots; "grpc://" and no scheme are plaintext, for loopback or a trusted network.
 */
#ifndef CAMDIRECTOR_H
#define CAMDIRECTOR_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Status codes. Values 0..16 are gRPC's (the server's errors pass through unchanged, see the
 * Errors table of docs/protocol.md); the SDK uses the same codes for what it refuses itself. */
typedef enum cd_status {
  CD_OK = 0,
  CD_CANCELLED = 1,
  CD_UNKNOWN = 2,
  CD_INVALID_ARGUMENT = 3,     /* NaN or infinite number, unparseable address, bad slot, ... */
  CD_DEADLINE_EXCEEDED = 4,    /* a blocking call's timeout_s passed */
  CD_NOT_FOUND = 5,            /* unknown session or id (from the server), no pose yet (poll) */
  CD_ALREADY_EXISTS = 6,
  CD_PERMISSION_DENIED = 7,    /* the key's role may not make this call */
  CD_RESOURCE_EXHAUSTED = 8,   /* too many states in one frame, or the server's limits */
  CD_FAILED_PRECONDITION = 9,  /* no session open, or one already open */
  CD_ABORTED = 10,
  CD_OUT_OF_RANGE = 11,        /* a frame number not greater than the last, a time going back */
  CD_UNIMPLEMENTED = 12,
  CD_INTERNAL = 13,
  CD_UNAVAILABLE = 14,         /* the server is down, refuses connections, or lost the session */
  CD_DATA_LOSS = 15,
  CD_UNAUTHENTICATED = 16      /* no key, an unknown one or a revoked one */
} cd_status;

/* "OK", "INVALID_ARGUMENT", ... (a static string; never NULL). */
const char* cd_status_name(int status);

typedef struct cd_vec3 {
  double x, y, z;
} cd_vec3;

typedef struct cd_quat {
  double x, y, z, w;
} cd_quat;

/* Local-to-world: world = position + rotation * (scale * local). For zero-initialised structs,
 * an all-zero rotation means the identity and an all-zero scale means (1, 1, 1). */
typedef struct cd_transform {
  cd_vec3 position; /* metres */
  cd_quat rotation; /* (x, y, z, w), unit length */
  cd_vec3 scale;
} cd_transform;

/* ---------------------------------------------------------------------------------------------
 * Client
 * ------------------------------------------------------------------------------------------- */

typedef struct cd_client cd_client; /* opaque */

/* Zero means the default for every field; cd_config_init fills in the defaults. The strings are
 * read by cd_client_create only (the caller may free them on return). */
typedef struct cd_config {
  const char* address;      /* "HOST:PORT", "[IPv6]:PORT", "grpc://HOST:PORT", "unix:/path" (plaintext),
                               or "grpcs://HOST:PORT" (TLS) */
  uint32_t queue_capacity;  /* frames waiting to be sent; when full the oldest is dropped. 8 */
  uint32_t max_states;      /* object states per frame. 64 */
  uint32_t max_in_flight;   /* frames sent and not yet answered; more wait in the queue. 2 */
  double stall_timeout_s;   /* the former name of frame_timeout_s: when > 0 it is used instead. 0 */
  double reconnect_max_s;   /* longest wait between tries (reconnect, recreate), s. 0.5 */
  int wait_for_server;      /* 1: cd_session_open waits for an unreachable server until its
                               deadline (DEADLINE_EXCEEDED); 0: fails at once (UNAVAILABLE). 0 */
  uint32_t max_message_bytes; /* gRPC message size limit both ways. 64 MiB */
  uint32_t io_poll_interval_ms; /* 0: cd_frame_submit wakes the I/O thread (one futex wake, a few
                                   microseconds); N > 0: it never does, the I/O thread looks at the
                                   queue every N ms instead (adds up to N ms to the pose's delay). 0 */
  const char* key;          /* the API key, sent with every call (Keys and TLS, above); NULL or "":
                               the CAMDIRECTOR_KEY environment variable, else no key */
  const char* ca_file;      /* grpcs:// only: a PEM file of the certificate authorities to trust
                               for the server's certificate; NULL or "": the system's roots */
  /* Appended in 0.2 (issue 40; Retries below). Zero takes the default, as above. */
  double retry_window_s;    /* a broken session is tried again (streams reopened, the session
                               recreated) until this long after the first failure since its last
                               answer; then CD_EVENT_SESSION_FAILED (UNAVAILABLE). 30 */
  double initial_backoff_s; /* the first wait before trying again; each next one doubles up to
                               reconnect_max_s, with equal jitter (half fixed, half random). 0.1 */
  double frame_timeout_s;   /* a frame in flight unanswered this long: the node is taken as hung,
                               the stream reopened and its unanswered frames sent again. 3 */
  uint32_t resend_history_frames; /* frames sent kept to send again: the unanswered ones on a new
                                     stream, and those a DATA_LOSS "resend from K" asks for. 600 */
  double (*random)(void* user); /* the jitter's random numbers in [0, 1) (e.g. seeded, for a
                                   replay); NULL: the SDK's own generator */
  void* random_user;        /* passed to random */
} cd_config;

void cd_config_init(cd_config* config);

/* This SDK's release, e.g. "0.2.0": the same as the server's it was released with (a server says
 * its own in /healthz and in every call's initial metadata, camdirector-version). */
const char* cd_version(void);

/* The wire contract's revision this SDK speaks (docs/protocol.md, "Versions"): CreateSession says
 * it in CreateSessionRequest.client_protocol (where a request given to cd_session_open_serialized
 * leaves that 0) and every call carries it as the metadata camdirector-protocol. A server that
 * speaks an older protocol refuses cd_session_open with CD_FAILED_PRECONDITION, its message
 * (cd_last_error) naming both. CD_PROTOCOL is this header's, cd_protocol() the library's. */
#define CD_PROTOCOL 1
uint32_t cd_protocol(void);

/* Whether an address parses (see cd_config.address): CD_OK, or CD_INVALID_ARGUMENT with the
 * reason copied into buf (may be NULL). */
cd_status cd_check_address(const char* address, char* buf, size_t size);

/* Whether cd_client_create takes the config: CD_OK, or CD_INVALID_ARGUMENT with the reason copied
 * into buf (may be NULL): an address that does not parse, a key with a space or a character a
 * header cannot carry (the reason never shows the key), a ca_file without grpcs:// or that cannot
 * be read or holds no PEM certificate, a queue or timeout out of range. */
cd_status cd_check_config(const cd_config* config, char* buf, size_t size);

/* Parses the address, reads the key and the CA file, and starts the I/O thread; does not connect
 * yet and does not block. CD_INVALID_ARGUMENT for a config cd_check_config refuses (*out is then
 * NULL). */
cd_status cd_client_create(const cd_config* config, cd_client** out);

/* BLOCKING (up to about 1 s): closes the open session if any (best effort), stops the I/O thread
 * and frees everything. Call it once no other call on this client is running. NULL is allowed. */
void cd_client_destroy(cd_client* client);

/* The message of the last failure of a blocking call on this client ("" if none), copied into
 * buf (always NUL-terminated when size > 0). Returns that failure's status. */
cd_status cd_last_error(cd_client* client, char* buf, size_t size);

/* ---------------------------------------------------------------------------------------------
 * Scene description (CreateSessionRequest as plain structs)
 * ------------------------------------------------------------------------------------------- */

typedef enum cd_shape {
  CD_SHAPE_BOX = 1,       /* box_size: full extents, m */
  CD_SHAPE_SPHERE = 2,    /* radius */
  CD_SHAPE_CYLINDER = 3,  /* radius, height; axis along local +Y, centred */
  CD_SHAPE_CAPSULE = 4,   /* radius, height (total, caps included) */
  CD_SHAPE_TRIANGLES = 5  /* vertices (x, y, z triples, m) and indices (3 per triangle, CCW) */
} cd_shape;

typedef struct cd_mesh {
  int shape; /* cd_shape */
  cd_vec3 box_size;
  double radius;
  double height;
  const float* vertices;
  uint32_t vertex_count; /* vertices, not floats */
  const uint32_t* indices;
  uint32_t index_count;  /* indices, a multiple of 3 */
} cd_mesh;

typedef struct cd_object {
  const char* id;
  cd_mesh mesh;
  cd_transform transform;
  int dynamic; /* 1: may move (then it has a slot) */
} cd_object;

typedef struct cd_target {
  const char* id;
  cd_mesh mesh;
  cd_transform transform;
  cd_vec3 aim_offset; /* the framed point, in the target's local frame */
  uint32_t team;      /* RIG_MATCH only */
  /* Shown to people only, never an identity; UTF-8, at most 64 code points, no control
   * character; NULL or "" shows the id. team_name is RIG_MATCH's. */
  const char* display_name;
  const char* team_name;
} cd_target;

/* Enum fields take the proto's numbers (0 is the default); the optional doubles and the screen
 * points are unset when NaN, which cd_style_init puts there (unset takes the server's default).
 * docs/protocol.md's Style table gives every default and range. */
typedef struct cd_style {
  double screen_a_x, screen_a_y; /* NaN: (-1/3, 0) */
  double screen_b_x, screen_b_y; /* NaN: (1/3, 0) */
  int visibility;                /* camdirector.v1.VisibilityMode; 0: FRAMING_ONLY */
  double gaze_room_m;
  double preferred_theta_ratio;
  double preferred_phi_deg;
  double response_time_s;
  double max_speed_m_s;
  double max_accel_m_s2;
  int mask;                      /* camdirector.v1.StyleMask */
  uint32_t map_resolution;       /* 0: 64 */
  int map_backend;               /* camdirector.v1.MapBackend */
  int rig;                       /* camdirector.v1.Rig; 0: RIG_TORIC */
  int shot_size;                 /* camdirector.v1.ShotSize (RIG_TRACKS) */
  int movement;                  /* camdirector.v1.Movement (RIG_TRACKS) */
  int match_director;            /* camdirector.v1.MatchDirector (RIG_MATCH) */
  double min_shot_s;             /* RIG_MATCH */
  double max_shot_s;             /* RIG_MATCH */
} cd_style;

void cd_style_init(cd_style* style);

/* Also send every answered pose as UDP datagrams in a camera-tracking format (docs/protocol.md,
 * "Pose outputs"): for Unreal Live Link's FreeD or OpenTrackIO source and other tools. */
typedef enum cd_pose_format {
  CD_POSE_FORMAT_OPENTRACKIO_JSON = 1,
  CD_POSE_FORMAT_OPENTRACKIO_CBOR = 2,
  CD_POSE_FORMAT_FREED_D1 = 3
} cd_pose_format;

typedef struct cd_pose_output {
  int format;              /* cd_pose_format */
  const char* address;     /* "udp://HOST:PORT", IPv4 */
  uint32_t source_number;  /* OpenTrackIO sourceNumber [1, 200], FreeD camera id [1, 255]; 0: 1 */
  double sensor_height_mm; /* what the focal length is stated for, [1, 100]; 0: 24 */
} cd_pose_output;

typedef struct cd_session_desc {
  const cd_object* objects;
  uint32_t object_count;
  const cd_target* targets;
  uint32_t target_count;
  double vertical_fov_deg; /* 0: 50 */
  double aspect;           /* width / height; 0: 16/9 */
  cd_style style;
  uint64_t seed;
  int record;
  const char* level_id;    /* RIG_TRACKS / RIG_MATCH; NULL or "" for none */
  double delay_s;          /* RIG_MATCH broadcast delay */
  const cd_pose_output* pose_outputs; /* at most 8 */
  uint32_t pose_output_count;
} cd_session_desc;

/* Zeroes the description and runs cd_style_init on its style. */
void cd_session_desc_init(cd_session_desc* desc);

/* ---------------------------------------------------------------------------------------------
 * Session (BLOCKING calls, each with a deadline)
 * ------------------------------------------------------------------------------------------- */

/* BLOCKING: CreateSession, then the I/O thread streams the frames. The description is copied
 * (the caller may free it on return). Slots: targets first, in order, then the dynamic objects
 * in order (cd_session_slot finds one by id). Fails with CD_FAILED_PRECONDITION when a session
 * is open, CD_INVALID_ARGUMENT for a description the SDK or server refuses, CD_UNAVAILABLE or
 * CD_DEADLINE_EXCEEDED when the server cannot be reached in time. */
cd_status cd_session_open(cd_client* client, const cd_session_desc* desc, double timeout_s);

/* BLOCKING: the same from a serialized camdirector.v1.CreateSessionRequest, for fields the plain
 * structs do not carry (glTF or OBJ meshes, newer fields). Slots as above. */
cd_status cd_session_open_serialized(cd_client* client, const void* request, size_t size, double timeout_s);

/* BLOCKING: UpdateStyle; on success the style is also kept for a recreated session. */
cd_status cd_session_update_style(cd_client* client, const cd_style* style, double timeout_s);

typedef struct cd_shot {
  int kind;           /* camdirector.v1.ShotKind */
  int held;
  char subjects[256]; /* subject ids joined by ',' (truncated) */
  char reason[256];
} cd_shot;

/* BLOCKING: TakeShot (RIG_MATCH): hold the given players, or release = 1 to give the program back.
 * kind is a camdirector.v1.ShotKind (0: chosen from the count). out may be NULL. */
cd_status cd_session_take_shot(cd_client* client, const char* const* subject_ids, uint32_t subject_count,
                               int kind, int release, cd_shot* out, double timeout_s);

/* BLOCKING: waits until every frame submitted so far has been answered or given up (dropped from
 * the queue, refused, or the session recreated or failed); a frame a broken stream left unanswered
 * is sent again and waited for. CD_DEADLINE_EXCEEDED if that takes over timeout_s. */
cd_status cd_session_flush(cd_client* client, double timeout_s);

/* BLOCKING: ends the stream (frames not yet answered are given up) and closes the session;
 * frames_answered (may be NULL) gets the server's count. The client may open another session. */
cd_status cd_session_close(cd_client* client, uint64_t* frames_answered, double timeout_s);

/* NON-BLOCKING: the current session id (changes only when the session is recreated, never when
 * the server restores it), "" when none. */
cd_status cd_session_id(cd_client* client, char* buf, size_t size);

/* NON-BLOCKING: the slot of a target or dynamic object id, -1 if the session has none such. */
int32_t cd_session_slot(cd_client* client, const char* id);

/* ---------------------------------------------------------------------------------------------
 * Frames (GAME THREAD, NON-BLOCKING, no allocation)
 * ------------------------------------------------------------------------------------------- */

typedef struct cd_state {
  uint32_t slot;          /* see cd_session_open */
  cd_transform transform; /* world transform, our frame */
} cd_state;

/* Copies the frame into the send queue (dropping the oldest queued frame when full) and returns.
 * Refused, with nothing queued: CD_INVALID_ARGUMENT for a NaN or infinite number or an unknown
 * slot, CD_OUT_OF_RANGE for a frame not greater than the last submitted or a time before the
 * last, CD_RESOURCE_EXHAUSTED for more than max_states states, CD_FAILED_PRECONDITION when no
 * session is open or it failed for good. States not sent keep their last transform. */
cd_status cd_frame_submit(cd_client* client, uint64_t frame, double time_s, const cd_state* states,
                          uint32_t state_count);

/* The camera of the newest answered frame. */
typedef struct cd_pose {
  uint64_t frame;          /* the frame this pose answers */
  double time_s;           /* that frame's game time */
  cd_vec3 position;        /* m, our frame */
  cd_quat rotation;        /* camera-to-world (x, y, z, w); the camera looks down local -Z */
  double vertical_fov_deg;
  int cut;                 /* this answer is a cut: do not blend or interpolate across it */
  int cut_since_last_poll; /* some answer since the previous poll was a cut */
  uint32_t shot_id;
  double visibility;       /* the rig's own estimate, [0, 1] */
  double compute_ms;       /* server time for this frame */
  uint32_t generation;     /* 1 for the opened session, +1 on each recreation */
  double received_s;       /* steady-clock seconds (cd_now_s) when the answer arrived */
} cd_pose;

/* NON-BLOCKING: copies the newest pose into *out. CD_NOT_FOUND while no frame has been answered
 * (*out untouched). Stale answers (frames not newer than the last) and MATCH replies still
 * buffering their delay carry no new pose and do not replace it. */
cd_status cd_pose_poll(cd_client* client, cd_pose* out);

typedef enum cd_event_kind {
  CD_EVENT_STREAMING = 1,      /* the first answer of the session's first stream */
  CD_EVENT_DISCONNECTED = 2,   /* the stream broke (status, message); reconnecting */
  CD_EVENT_RESUMED = 3,        /* a new stream answers on the same session id (restored or kept) */
  CD_EVENT_RECREATED = 4,      /* the server lost the session: created again, new id */
  CD_EVENT_SESSION_FAILED = 5, /* recreating was refused for good, or the key was (status); streaming stopped */
  CD_EVENT_FRAME_REFUSED = 6   /* the server refused a frame (status); the session goes on */
} cd_event_kind;

typedef struct cd_event {
  int kind;              /* cd_event_kind */
  int status;            /* cd_status of what happened (CD_OK for good news) */
  uint32_t generation;
  uint64_t frame;        /* the newest frame submitted when it happened */
  double time_s;         /* cd_now_s() when it happened */
  char session_id[64];
  char message[192];
} cd_event;

/* NON-BLOCKING: pops the oldest unread event into *out; CD_NOT_FOUND when there is none. The
 * last 64 are kept (older ones are dropped and counted in cd_stats.events_dropped). */
cd_status cd_event_poll(cd_client* client, cd_event* out);

typedef enum cd_state_kind {
  CD_STATE_NO_SESSION = 0,
  CD_STATE_CONNECTING = 1,   /* a stream is being opened */
  CD_STATE_STREAMING = 2,
  CD_STATE_RECONNECTING = 3, /* waiting to try again */
  CD_STATE_RECREATING = 4,   /* creating the session again */
  CD_STATE_FAILED = 5        /* the session is lost for good; open another */
} cd_state_kind;

typedef struct cd_stats {
  int state;                   /* cd_state_kind */
  uint32_t generation;
  uint64_t frames_submitted;   /* accepted by cd_frame_submit */
  uint64_t frames_refused;     /* refused by cd_frame_submit (NaN, order, slot, size) */
  uint64_t frames_dropped;     /* pushed out of the full queue by newer ones */
  uint64_t frames_sent;        /* frames written on a stream, those sent again included */
  uint64_t frames_answered;    /* answers received, stale ones included */
  uint64_t frames_stale;
  uint64_t frames_lost;        /* sent but unanswered when a stream broke, and not sent again
                                  (refused by the server, or the session was recreated) */
  uint64_t streams_opened;
  uint64_t disconnects;
  uint64_t resumes;
  uint64_t recreations;
  uint64_t events_dropped;
  uint32_t queued;             /* frames waiting now */
  uint32_t in_flight;          /* frames sent and unanswered now */
  int last_stream_status;      /* cd_status that ended the last stream */
} cd_stats;

/* NON-BLOCKING: a snapshot of the counters. */
void cd_client_stats(cd_client* client, cd_stats* out);

/* A monotonic clock in seconds (the one cd_pose.received_s and cd_event.time_s use). */
double cd_now_s(void);

/* ---------------------------------------------------------------------------------------------
 * Coordinate conversions (docs/protocol.md, "From Unity and Unreal"; pure functions)
 *
 * Unity: left-handed, +Y up, +Z forward, metres.      ours = (x, y, -z); q = (-x, -y, z, w)
 * Unreal: left-handed, +Z up, +X forward, +Y right, cm. ours = (y, z, -x) / 100;
 *         q = (-qy, -qz, qx, qw); scale = (sy, sz, sx)
 * An engine camera's rotation converts unchanged to ours (forward/right/up -> -Z/+X/+Y).
 * ------------------------------------------------------------------------------------------- */

cd_vec3 cd_from_unity_position(cd_vec3 p);
cd_vec3 cd_to_unity_position(cd_vec3 p);
cd_quat cd_from_unity_rotation(cd_quat q);
cd_quat cd_to_unity_rotation(cd_quat q);
cd_vec3 cd_from_unity_scale(cd_vec3 s);
cd_vec3 cd_to_unity_scale(cd_vec3 s);

cd_vec3 cd_from_unreal_position(cd_vec3 p_cm);
cd_vec3 cd_to_unreal_position(cd_vec3 p_m);
cd_quat cd_from_unreal_rotation(cd_quat q);
cd_quat cd_to_unreal_rotation(cd_quat q);
cd_vec3 cd_from_unreal_scale(cd_vec3 s);
cd_vec3 cd_to_unreal_scale(cd_vec3 s);

cd_transform cd_from_unity_transform(cd_transform t);
cd_transform cd_from_unreal_transform(cd_transform t);

/* Position (m) and rotation of a Unity camera (looks down +Z) showing what the pose shows.
 * Unity's Camera.fieldOfView is vertical: use pose->vertical_fov_deg as it is. */
void cd_camera_pose_to_unity(const cd_pose* pose, cd_vec3* position, cd_quat* rotation);
/* Position (cm) and FQuat of an Unreal camera (looks down +X); its FieldOfView is horizontal. */
void cd_camera_pose_to_unreal(const cd_pose* pose, cd_vec3* position_cm, cd_quat* rotation);

/* Horizontal field of view, degrees, of a vertical one at aspect = width / height, and back. */
double cd_horizontal_fov_deg(double vertical_fov_deg, double aspect);
double cd_vertical_fov_deg(double horizontal_fov_deg, double aspect);

/* In place, for engine meshes: converts vertex_count (x, y, z) triples to our frame, and reverses
 * the winding of index_count / 3 triangles (engines' front faces are clockwise, ours CCW). */
void cd_from_unity_vertices(float* xyz, uint32_t vertex_count);
void cd_from_unreal_vertices(float* xyz_cm, uint32_t vertex_count);
void cd_flip_winding(uint32_t* indices, uint32_t index_count);

#ifdef __cplusplus
}
#endif

#endif /* CAMDIRECTOR_H */
