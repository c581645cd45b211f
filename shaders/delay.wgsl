// The delay layer on the GPU: one invocation per environment copy. Mirrors src/delay/cpu.rs
// step for step, over the same buffer layout (src/delay/layout.rs), so both produce identical
// augmented states and step records.

struct Params {
    copies: u32,
    obs_dim: u32,
    act_dim: u32,
    delay: u32,
    ring_len: u32,
    stride: u32,     // obs_dim + act_dim + 1: state, action, reward
    slots: u32,      // record slots per copy: delay + 2
    aug_dim: u32,    // obs_dim + delay * act_dim
    in_stride: u32,  // act_dim + 1 + obs_dim: action, reward, next state
    reset_base: u32, // offset of the reset states after the copies' input rows
    _pad0: u32,
    _pad1: u32,
}

struct CopyCounters {
    t: u32,
    episode: u32,
    cursor: u32,
    ready: u32,
    record_count: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

struct RecordMeta {
    tau: u32,
    episode: u32,
    flags: u32,
    slot: u32,
}

const RECORD_TERMINATED: u32 = 1u;
const RECORD_TRUNCATED: u32 = 2u;
const RECORD_FINAL_STATE: u32 = 4u;
// input_flags bits: 1 terminated, 2 truncated, 4 held (no step), 8 restarted (a new episode
// in place of a step); bits 4.. the row of the new episode's first state (where done or
// restarted).
const IN_TERMINATED: u32 = 1u;
const IN_TRUNCATED: u32 = 2u;
const IN_HELD: u32 = 4u;
const IN_RESTART: u32 = 8u;

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read_write> counters: array<CopyCounters>;
@group(0) @binding(2) var<storage, read_write> ring: array<f32>;
@group(0) @binding(3) var<storage, read_write> augmented: array<f32>;
@group(0) @binding(4) var<storage, read_write> record_meta: array<RecordMeta>;
@group(0) @binding(5) var<storage, read_write> record_data: array<f32>;
@group(0) @binding(6) var<storage, read> input: array<f32>;
@group(0) @binding(7) var<storage, read> input_flags: array<u32>;

fn ring_base(copy: u32) -> u32 {
    return copy * params.ring_len * params.stride;
}

// x_t from the ring, or zeros while t < delay.
fn update_augmented(copy: u32) {
    let c = counters[copy];
    let out = copy * params.aug_dim;
    if (c.t < params.delay) {
        counters[copy].ready = 0u;
        for (var j = 0u; j < params.aug_dim; j++) {
            augmented[out + j] = 0.0;
        }
        return;
    }
    counters[copy].ready = 1u;
    let base = ring_base(copy);
    let oldest = (c.cursor + params.ring_len - params.delay) % params.ring_len;
    for (var j = 0u; j < params.obs_dim; j++) {
        augmented[out + j] = ring[base + oldest * params.stride + j];
    }
    for (var k = 0u; k < params.delay; k++) {
        let s = (oldest + k) % params.ring_len;
        for (var j = 0u; j < params.act_dim; j++) {
            augmented[out + params.obs_dim + k * params.act_dim + j] = ring[base + s * params.stride + params.obs_dim + j];
        }
    }
}

// Writes s_0 (read from input[first_state ..]) at the cursor, advanced first when `advance`.
fn start_episode(copy: u32, first_state: u32, advance: bool) {
    if (advance) {
        counters[copy].cursor = (counters[copy].cursor + 1u) % params.ring_len;
    }
    counters[copy].t = 0u;
    let at = ring_base(copy) + counters[copy].cursor * params.stride;
    for (var j = 0u; j < params.obs_dim; j++) {
        ring[at + j] = input[first_state + j];
    }
    for (var j = params.obs_dim; j < params.stride; j++) {
        ring[at + j] = 0.0;
    }
    update_augmented(copy);
}

// Copies step `tau` of the current episode out of the ring into the next record slot.
fn emit_record(copy: u32, tau: u32, flags: u32) {
    let c = counters[copy];
    let slot = (c.cursor + params.ring_len - (c.t - tau)) % params.ring_len;
    let row = copy * params.slots + c.record_count;
    record_meta[row] = RecordMeta(tau, c.episode, flags, slot);
    let source = ring_base(copy) + slot * params.stride;
    for (var j = 0u; j < params.stride; j++) {
        record_data[row * params.stride + j] = ring[source + j];
    }
    counters[copy].record_count = c.record_count + 1u;
}

// Starts every copy's first episode; input holds the s_0 rows.
@compute @workgroup_size(64)
fn reset(@builtin(global_invocation_id) id: vec3<u32>) {
    let copy = id.x;
    if (copy >= params.copies) {
        return;
    }
    counters[copy] = CopyCounters(0u, 0u, 0u, 0u, 0u, 0u, 0u, 0u);
    let base = ring_base(copy);
    for (var j = 0u; j < params.ring_len * params.stride; j++) {
        ring[base + j] = 0.0;
    }
    start_episode(copy, copy * params.obs_dim, false);
}

// One step of one copy: store a_t, r_t beside s_t, store s_{t+1}, emit the records that
// completed, start the next episode where this one ended, and rebuild x.
@compute @workgroup_size(64)
fn step(@builtin(global_invocation_id) id: vec3<u32>) {
    let copy = id.x;
    if (copy >= params.copies) {
        return;
    }
    let in_row = copy * params.in_stride;
    let flags_in = input_flags[copy];
    if ((flags_in & IN_HELD) != 0u) {
        counters[copy].record_count = 0u;
        return;
    }
    if ((flags_in & IN_RESTART) != 0u) {
        counters[copy].record_count = 0u;
        counters[copy].episode = counters[copy].episode + 1u;
        start_episode(copy, params.reset_base + (flags_in >> 4u) * params.obs_dim, true);
        return;
    }
    let terminated = (flags_in & IN_TERMINATED) != 0u;
    let truncated = (flags_in & IN_TRUNCATED) != 0u;
    let done = terminated || truncated;
    let base = ring_base(copy);

    var at = base + counters[copy].cursor * params.stride;
    for (var j = 0u; j < params.act_dim; j++) {
        ring[at + params.obs_dim + j] = input[in_row + j];
    }
    ring[at + params.stride - 1u] = input[in_row + params.act_dim];
    counters[copy].cursor = (counters[copy].cursor + 1u) % params.ring_len;
    counters[copy].t = counters[copy].t + 1u;
    at = base + counters[copy].cursor * params.stride;
    for (var j = 0u; j < params.obs_dim; j++) {
        ring[at + j] = input[in_row + params.act_dim + 1u + j];
    }
    for (var j = params.obs_dim; j < params.stride; j++) {
        ring[at + j] = 0.0;
    }
    counters[copy].record_count = 0u;

    // Record tau completes when s_{tau+1} arrives: tau = t - delay - 1; an episode end
    // delivers the rest at once.
    let t = i32(counters[copy].t);
    let first = t - i32(params.delay) - 1;
    var end = max(first + 1, 0);
    if (done) {
        end = t;
    }
    for (var tau = max(first, 0); tau < end; tau++) {
        var flags = 0u;
        if (tau == t - 1 && terminated) {
            flags |= RECORD_TERMINATED;
        }
        if (tau == t - 1 && truncated) {
            flags |= RECORD_TRUNCATED;
        }
        emit_record(copy, u32(tau), flags);
    }
    if (done) {
        var flags = RECORD_FINAL_STATE;
        if (terminated) {
            flags |= RECORD_TERMINATED;
        }
        if (truncated) {
            flags |= RECORD_TRUNCATED;
        }
        emit_record(copy, counters[copy].t, flags);
        counters[copy].episode = counters[copy].episode + 1u;
        start_episode(copy, params.reset_base + (flags_in >> 4u) * params.obs_dim, true);
    } else {
        update_augmented(copy);
    }
}
