//! The delay layer on a GPU: the ring buffers, augmented states and step records live in
//! `wgpu` storage buffers and `shaders/delay.wgsl` updates them, one invocation per copy.
//! Each step uploads only what the simulator produced (actions, rewards, flags, new states, and
//! the first states of episodes that restarted); results are read back only on request.
use std::io::{Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError, Weak};

use bytemuck::{Pod, Zeroable};
use wgpu::util::DeviceExt;

use super::config::check_len;
use super::cpu::transitions_from;
use super::layer::{DelayLayer, LayerState, LayerStateMut, read_state, write_state};
use super::layout::{CopyCounters, DelayLayout, RecordMeta};
use super::records::{RecordBatch, StepInput};
use super::transitions::Transitions;
use super::warmup::WarmupFiller;
use super::{DelayConfig, DelayError};
use crate::sim::CopyStep;
use crate::snapshot::SnapshotError;

#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error("no GPU adapter available ({0}); the CPU delay layer is the fallback")]
    NoAdapter(String),
    #[error("the GPU device could not be opened: {0}")]
    Device(String),
    #[error(
        "{what} needs {bytes} bytes, above this device's storage buffer limit of {limit} bytes; use fewer copies or a shorter delay"
    )]
    TooLarge {
        what: &'static str,
        bytes: u64,
        limit: u64,
    },
    #[error("reading back from the GPU failed: {0}")]
    Readback(String),
    #[error(transparent)]
    Delay(#[from] DelayError),
}

/// The uniform block of `shaders/delay.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct Params {
    copies: u32,
    obs_dim: u32,
    act_dim: u32,
    delay: u32,
    ring_len: u32,
    stride: u32,
    slots: u32,
    aug_dim: u32,
    in_stride: u32,
    reset_base: u32,
    _pad: [u32; 2],
}

const WORKGROUP: u32 = 64;
/// `input_flags` bits beside terminated (1) and truncated (2), as `shaders/delay.wgsl` reads
/// them; bits 4.. hold the row of the copy's new first state, where it starts an episode.
const IN_HELD: u32 = 4;
const IN_RESTART: u32 = 8;

/// The device the delay layers of this process share, with the two pipelines compiled once:
/// the training layer and each evaluation's layer run on one device, so an evaluation pays
/// neither a Vulkan device nor a shader compilation, and no device is torn down while another
/// runs (opening and dropping Mesa's software Vulkan devices beside a live one crashed a test
/// run on CI, once, with a corrupted heap). It lives while a layer holds it.
struct SharedGpu {
    adapter_name: String,
    limits: wgpu::Limits,
    device: wgpu::Device,
    queue: wgpu::Queue,
    bind_group_layout: wgpu::BindGroupLayout,
    reset_pipeline: wgpu::ComputePipeline,
    step_pipeline: wgpu::ComputePipeline,
    /// Set by wgpu when the device is lost: the next layer opens a new one.
    lost: Arc<AtomicBool>,
}

/// The device a new layer runs on: the one the live layers share, or, where there is none or
/// it was lost, a new one (the first GPU adapter, software ones included).
fn shared_gpu() -> Result<Arc<SharedGpu>, GpuError> {
    static SHARED: Mutex<Weak<SharedGpu>> = Mutex::new(Weak::new());
    // Held while a device opens, so that layers made at once share one.
    let mut shared = SHARED.lock().unwrap_or_else(PoisonError::into_inner);
    if let Some(gpu) = shared.upgrade()
        && !gpu.lost.load(Ordering::Relaxed)
    {
        return Ok(gpu);
    }
    let gpu = Arc::new(open_gpu()?);
    *shared = Arc::downgrade(&gpu);
    Ok(gpu)
}

fn open_gpu() -> Result<SharedGpu, GpuError> {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        ..Default::default()
    }))
    .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
    let info = adapter.get_info();
    let adapter_name = format!("{} ({:?}, {:?})", info.name, info.device_type, info.backend);
    let limits = adapter.limits();
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("dhrl delay layer"),
        required_limits: limits.clone(),
        ..Default::default()
    }))
    .map_err(|e| GpuError::Device(e.to_string()))?;
    let lost = Arc::new(AtomicBool::new(false));
    let on_loss = Arc::clone(&lost);
    device.set_device_lost_callback(move |_, _| on_loss.store(true, Ordering::Relaxed));

    let module = device.create_shader_module(wgpu::include_wgsl!("../../shaders/delay.wgsl"));
    // One layout for both entry points: binding 0 the parameters, 1..=5 the state and
    // outputs, 6..=7 the step inputs.
    let buffer_entry = |binding: u32, ty: wgpu::BufferBindingType| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    };
    let entries: Vec<_> = (0..8)
        .map(|binding| match binding {
            0 => buffer_entry(0, wgpu::BufferBindingType::Uniform),
            1..=5 => buffer_entry(
                binding,
                wgpu::BufferBindingType::Storage { read_only: false },
            ),
            _ => buffer_entry(
                binding,
                wgpu::BufferBindingType::Storage { read_only: true },
            ),
        })
        .collect();
    let bind_group_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("delay layer"),
        entries: &entries,
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("delay layer"),
        bind_group_layouts: &[Some(&bind_group_layout)],
        immediate_size: 0,
    });
    let pipeline = |entry: &str| {
        device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(entry),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some(entry),
            compilation_options: Default::default(),
            cache: None,
        })
    };
    let (reset_pipeline, step_pipeline) = (pipeline("reset"), pipeline("step"));

    Ok(SharedGpu {
        adapter_name,
        limits,
        device,
        queue,
        bind_group_layout,
        reset_pipeline,
        step_pipeline,
        lost,
    })
}

/// The GPU implementation of the delay layer. Same outputs as [`super::CpuDelayLayer`].
pub struct GpuDelayLayer {
    layout: DelayLayout,
    gpu: Arc<SharedGpu>,
    /// Kept alive for the bind group; never read from the host.
    _params: wgpu::Buffer,
    ring: wgpu::Buffer,
    counters: wgpu::Buffer,
    augmented: wgpu::Buffer,
    record_meta: wgpu::Buffer,
    record_data: wgpu::Buffer,
    /// Grown on demand: `[N, act + 1 + obs]` rows, then the reset states.
    input: wgpu::Buffer,
    input_flags: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    input_scratch: Vec<f32>,
    flags_scratch: Vec<u32>,
    warmup: WarmupFiller,
    /// Host copies of the outputs, read back after every [`DelayLayer`] step.
    host_counters: Vec<CopyCounters>,
    host_augmented: Vec<f32>,
    host_ready: Vec<u32>,
    host_records: RecordBatch,
}

impl GpuDelayLayer {
    /// Allocates the buffers on the device that this process's live layers share (opened by the
    /// first of them).
    pub fn new(
        config: &DelayConfig,
        copies: usize,
        obs_dim: usize,
        action_low: &[f64],
        action_high: &[f64],
        seed: u64,
    ) -> Result<GpuDelayLayer, GpuError> {
        let layout = DelayLayout::for_config(config, copies, obs_dim, action_low.len())?;
        let delay = layout.delay;
        let gpu = shared_gpu()?;
        let (device, limits) = (&gpu.device, &gpu.limits);

        let n = copies as u64;
        let f32s = size_of::<f32>() as u64;
        let sizes = [
            (
                "the ring buffers",
                n * (layout.ring_len() * layout.stride()) as u64 * f32s,
            ),
            (
                "the augmented states",
                n * layout.augmented_dim() as u64 * f32s,
            ),
            (
                "the step records",
                n * (layout.record_slots() * layout.stride()) as u64 * f32s,
            ),
            (
                "the step inputs",
                n * 2 * (obs_dim + layout.act_dim + 1) as u64 * f32s,
            ),
        ];
        let limit = u64::from(limits.max_storage_buffer_binding_size).min(limits.max_buffer_size);
        if let Some(&(what, bytes)) = sizes.iter().find(|(_, bytes)| *bytes > limit) {
            return Err(GpuError::TooLarge { what, bytes, limit });
        }

        let params = Params {
            copies: copies as u32,
            obs_dim: obs_dim as u32,
            act_dim: layout.act_dim as u32,
            delay: delay as u32,
            ring_len: layout.ring_len() as u32,
            stride: layout.stride() as u32,
            slots: layout.record_slots() as u32,
            aug_dim: layout.augmented_dim() as u32,
            in_stride: (layout.act_dim + 1 + obs_dim) as u32,
            reset_base: (copies * (layout.act_dim + 1 + obs_dim)) as u32,
            _pad: [0; 2],
        };
        let params_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("params"),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let storage = |label: &str, bytes: u64| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes.max(16),
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let counters = storage("counters", n * size_of::<CopyCounters>() as u64);
        let ring = storage("ring", sizes[0].1);
        let augmented = storage("augmented", sizes[1].1);
        let record_meta = storage(
            "record meta",
            n * layout.record_slots() as u64 * size_of::<RecordMeta>() as u64,
        );
        let record_data = storage("record data", sizes[2].1);
        let input = storage("input", sizes[3].1);
        let input_flags = storage("input flags", n * size_of::<u32>() as u64);
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("delay layer"),
            layout: &gpu.bind_group_layout,
            entries: &[
                &params_buffer,
                &counters,
                &ring,
                &augmented,
                &record_meta,
                &record_data,
                &input,
                &input_flags,
            ]
            .iter()
            .enumerate()
            .map(|(binding, buffer)| wgpu::BindGroupEntry {
                binding: binding as u32,
                resource: buffer.as_entire_binding(),
            })
            .collect::<Vec<_>>(),
        });
        Ok(GpuDelayLayer {
            layout,
            gpu,
            _params: params_buffer,
            ring,
            counters,
            augmented,
            record_meta,
            record_data,
            input,
            input_flags,
            bind_group,
            input_scratch: Vec::new(),
            flags_scratch: vec![0; copies],
            warmup: WarmupFiller::new(config.warmup, action_low, action_high, seed),
            host_counters: vec![CopyCounters::default(); copies],
            host_augmented: vec![0.0; copies * layout.augmented_dim()],
            host_ready: vec![0; copies],
            host_records: RecordBatch::new(layout),
        })
    }

    pub fn layout(&self) -> DelayLayout {
        self.layout
    }

    /// Name, type and backend of the adapter in use.
    pub fn adapter_name(&self) -> &str {
        &self.gpu.adapter_name
    }

    fn dispatch(&self, pipeline: &wgpu::ComputePipeline) {
        let mut encoder = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("delay step"),
            });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: None,
                timestamp_writes: None,
            });
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &self.bind_group, &[]);
            pass.dispatch_workgroups((self.layout.copies as u32).div_ceil(WORKGROUP), 1, 1);
        }
        self.gpu.queue.submit([encoder.finish()]);
    }

    /// Starts every copy's first episode from `observations` (`[N, obs_dim]`), on the device
    /// only (no readback).
    pub fn reset_device(&mut self, observations: &[f32]) -> Result<(), GpuError> {
        let l = self.layout;
        check_len(
            "initial observations",
            observations.len(),
            l.copies * l.obs_dim,
        )?;
        self.gpu
            .queue
            .write_buffer(&self.input, 0, bytemuck::cast_slice(observations));
        self.dispatch(&self.gpu.reset_pipeline);
        Ok(())
    }

    /// Uploads one step of the undelayed batch and runs the step kernel (no readback).
    pub fn step_device(&mut self, step: &StepInput<'_>) -> Result<(), GpuError> {
        let l = self.layout;
        step.check(&l)?;
        let (obs, act) = (l.obs_dim, l.act_dim);
        self.input_scratch.clear();
        // A copy starts an episode from its observations row where it ended one or restarted.
        let starts = |i: usize| match step.control(i) {
            CopyStep::Step => step.terminated[i] != 0 || step.truncated[i] != 0,
            CopyStep::Hold => false,
            CopyStep::Restart => true,
        };
        let mut resets = 0u32;
        for i in 0..l.copies {
            let done = step.terminated[i] != 0 || step.truncated[i] != 0;
            let next = if done {
                &step.final_observations
            } else {
                &step.observations
            };
            self.input_scratch
                .extend_from_slice(&step.actions[i * act..(i + 1) * act]);
            self.input_scratch.push(step.rewards[i]);
            self.input_scratch
                .extend_from_slice(&next[i * obs..(i + 1) * obs]);
            let control = match step.control(i) {
                CopyStep::Step => step.terminated[i] | (step.truncated[i] << 1),
                CopyStep::Hold => IN_HELD,
                CopyStep::Restart => IN_RESTART,
            };
            let starts = starts(i);
            self.flags_scratch[i] = control | if starts { resets << 4 } else { 0 };
            resets += u32::from(starts);
        }
        for i in (0..l.copies).filter(|&i| starts(i)) {
            self.input_scratch
                .extend_from_slice(&step.observations[i * obs..(i + 1) * obs]);
        }
        self.gpu
            .queue
            .write_buffer(&self.input, 0, bytemuck::cast_slice(&self.input_scratch));
        self.gpu.queue.write_buffer(
            &self.input_flags,
            0,
            bytemuck::cast_slice(&self.flags_scratch),
        );
        self.dispatch(&self.gpu.step_pipeline);
        Ok(())
    }

    /// Blocks until the device has finished every submitted step.
    pub fn wait(&self) -> Result<(), GpuError> {
        self.gpu
            .device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| GpuError::Readback(e.to_string()))
    }

    /// Copies a device buffer back to the host.
    fn read<T: Pod>(&self, buffer: &wgpu::Buffer, count: usize) -> Result<Vec<T>, GpuError> {
        let bytes = (count * size_of::<T>()) as u64;
        if bytes == 0 {
            return Ok(Vec::new());
        }
        let staging = self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("readback"),
            });
        encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, bytes);
        self.gpu.queue.submit([encoder.finish()]);
        let (sender, receiver) = std::sync::mpsc::channel();
        staging
            .slice(..)
            .map_async(wgpu::MapMode::Read, move |result| {
                let _ = sender.send(result);
            });
        self.gpu
            .device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        receiver
            .recv()
            .map_err(|e| GpuError::Readback(e.to_string()))?
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        let values = {
            let view = staging
                .slice(..)
                .get_mapped_range()
                .map_err(|e| GpuError::Readback(e.to_string()))?;
            bytemuck::cast_slice(&view).to_vec()
        };
        staging.unmap();
        Ok(values)
    }

    /// `[N, 2Δ + 3, obs + act + 1]`: every copy's ring.
    fn read_ring(&self) -> Result<Vec<f32>, GpuError> {
        let l = self.layout;
        self.read(&self.ring, l.copies * l.ring_len() * l.stride())
    }

    /// `[N, obs + Δ·act]`: `x_t` of every copy, read back from the device.
    pub fn read_augmented(&self) -> Result<Vec<f32>, GpuError> {
        self.read(
            &self.augmented,
            self.layout.copies * self.layout.augmented_dim(),
        )
    }

    /// Per-copy counters (readiness, step, episode, records of the last step).
    pub fn read_counters(&self) -> Result<Vec<CopyCounters>, GpuError> {
        self.read(&self.counters, self.layout.copies)
    }

    /// The step records completed by the last step, read back from the device.
    pub fn read_records(&self) -> Result<RecordBatch, GpuError> {
        self.read_records_counted(&self.read_counters()?)
    }

    /// The records, with the counts of `counters` (read back already).
    fn read_records_counted(&self, counters: &[CopyCounters]) -> Result<RecordBatch, GpuError> {
        let l = self.layout;
        let mut records = RecordBatch::new(l);
        records.set_counts(counters);
        records.meta = self.read(&self.record_meta, l.copies * l.record_slots())?;
        records.data = self.read(&self.record_data, l.copies * l.record_slots() * l.stride())?;
        Ok(records)
    }

    /// Reads the outputs of the last step back into the host copies.
    fn sync(&mut self) -> Result<(), GpuError> {
        self.host_counters = self.read_counters()?;
        self.host_augmented = self.read_augmented()?;
        for (ready, c) in self.host_ready.iter_mut().zip(&self.host_counters) {
            *ready = c.ready;
        }
        self.host_records = self.read_records_counted(&self.host_counters)?;
        Ok(())
    }
}

fn gpu_error(e: GpuError) -> DelayError {
    match e {
        GpuError::Delay(e) => e,
        e => DelayError::Gpu(e.to_string()),
    }
}

impl DelayLayer for GpuDelayLayer {
    fn layout(&self) -> DelayLayout {
        self.layout
    }

    fn reset(&mut self, observations: &[f32]) -> Result<(), DelayError> {
        self.reset_device(observations).map_err(gpu_error)?;
        self.sync().map_err(gpu_error)
    }

    fn step(&mut self, input: &StepInput<'_>) -> Result<(), DelayError> {
        self.step_device(input).map_err(gpu_error)?;
        self.sync().map_err(gpu_error)
    }

    fn fill_warmup(&mut self, actions: &mut [f32]) -> Result<(), DelayError> {
        self.warmup.fill(actions, &self.host_ready)
    }

    fn augmented(&self) -> &[f32] {
        &self.host_augmented
    }

    fn ready(&self) -> &[u32] {
        &self.host_ready
    }

    fn records(&self) -> &RecordBatch {
        &self.host_records
    }

    fn transitions(&self) -> Result<Transitions, DelayError> {
        let ring = self.read_ring().map_err(gpu_error)?;
        Ok(transitions_from(&self.layout, &ring, &self.host_records))
    }

    fn save(&self, out: &mut dyn Write) -> Result<(), SnapshotError> {
        let ring = self
            .read_ring()
            .map_err(|e| std::io::Error::other(e.to_string()))?;
        write_state(
            out,
            LayerState {
                counters: &self.host_counters,
                ring: &ring,
                augmented: &self.host_augmented,
                ready: &self.host_ready,
                records: &self.host_records,
                rng: self.warmup.rng(),
            },
        )
    }

    fn load(&mut self, input: &mut dyn Read) -> Result<(), SnapshotError> {
        let l = self.layout;
        let mut ring = vec![0.0f32; l.copies * l.ring_len() * l.stride()];
        read_state(
            input,
            LayerStateMut {
                counters: &mut self.host_counters,
                ring: &mut ring,
                augmented: &mut self.host_augmented,
                ready: &mut self.host_ready,
                records: &mut self.host_records,
                rng: self.warmup.rng_mut(),
            },
        )?;
        for (buffer, bytes) in [
            (&self.counters, bytemuck::cast_slice(&self.host_counters)),
            (&self.ring, bytemuck::cast_slice(&ring)),
            (&self.augmented, bytemuck::cast_slice(&self.host_augmented)),
            (
                &self.record_meta,
                bytemuck::cast_slice(&self.host_records.meta),
            ),
            (
                &self.record_data,
                bytemuck::cast_slice(&self.host_records.data),
            ),
        ] {
            self.gpu.queue.write_buffer(buffer, 0, bytes);
        }
        self.wait()
            .map_err(|e| std::io::Error::other(e.to_string()))?;
        Ok(())
    }
}
