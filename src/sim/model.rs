//! Loading a task's MuJoCo model once, for every copy to share.
use std::path::PathBuf;
use std::sync::{Arc, Mutex, Once};

use mujoco_rs::prelude::{MjData, MjModel, MjtObjBase};

use super::SimError;

/// MuJoCo's integration state (`mjSTATE_INTEGRATION`: time, positions, velocities, activations,
/// warm start, controls, applied forces, equality and mocap state, user data): everything in an
/// mjData that a later step reads.
pub(super) const INTEGRATION_STATE: u32 = mujoco_rs::prelude::MjtState::mjSTATE_INTEGRATION as u32;
use crate::tasks::{Progress, TaskDef, TaskName};

/// The folder [`set_assets_dir`] chose, if any.
static ASSETS_DIR: Mutex<Option<PathBuf>> = Mutex::new(None);

/// Makes `dir` the folder of the task XMLs for this process (the Python package points it at
/// the installed Gymnasium's `envs/mujoco/assets`); `$DHRL_ASSETS_DIR` still wins.
pub fn set_assets_dir(dir: PathBuf) {
    *ASSETS_DIR.lock().unwrap_or_else(|e| e.into_inner()) = Some(dir);
}

/// Where the task XMLs are: `$DHRL_ASSETS_DIR` at run time, else the folder given to
/// [`set_assets_dir`], else the folder `scripts/setup.sh` made, baked in at build time by
/// `.cargo/config.toml`.
pub fn assets_dir() -> PathBuf {
    std::env::var_os("DHRL_ASSETS_DIR")
        .map(PathBuf::from)
        .or_else(|| ASSETS_DIR.lock().unwrap_or_else(|e| e.into_inner()).clone())
        .or_else(|| option_env!("DHRL_ASSETS_DIR").map(PathBuf::from))
        .unwrap_or_else(|| PathBuf::from(".deps/mujoco-assets"))
}

/// Routes MuJoCo's messages to the `log` crate, so it never writes `MUJOCO_LOG.TXT`.
fn install_mujoco_logging() {
    static HOOK: Once = Once::new();
    // SAFETY: `Once` runs this before any model of ours is loaded or stepped.
    HOOK.call_once(|| unsafe { mujoco_rs::logging::install_logging_hook() });
}

/// A task's compiled model with the constants every copy needs.
pub struct TaskModel {
    pub task: &'static TaskDef,
    pub model: Arc<MjModel>,
    /// Seconds per environment step: `timestep · frame_skip`.
    pub dt: f64,
    pub nq: usize,
    pub nv: usize,
    /// `qpos0`, the state `mj_resetData` restores.
    pub init_qpos: Vec<f64>,
    /// The integration state `mj_resetData` leaves (`qpos0`; velocities, activations,
    /// controls, applied forces, warm start and time zero), for [`TaskModel::reset_data`].
    pub reset_state: Vec<f64>,
    /// Lower and upper control bounds (`actuator_ctrlrange`).
    pub action_low: Vec<f64>,
    pub action_high: Vec<f64>,
    /// Resolved [`Progress`]: body id for `BodyX`.
    pub progress_body: usize,
    /// Body masses and their total, for the centre of mass (Humanoid).
    pub body_mass: Vec<f64>,
    pub total_mass: f64,
}

impl TaskModel {
    pub fn load(name: TaskName) -> Result<Arc<TaskModel>, SimError> {
        install_mujoco_logging();
        let task = name.def();
        let path = assets_dir().join(task.xml);
        if !path.is_file() {
            return Err(SimError::MissingModel { path });
        }
        let model = MjModel::from_xml(&path).map_err(|e| SimError::LoadFailed {
            path: path.clone(),
            message: e.to_string(),
        })?;
        let ffi = model.ffi();
        let (nq, nv, nu) = (ffi.nq as usize, ffi.nv as usize, ffi.nu as usize);
        let dt = ffi.opt.timestep * task.frame_skip as f64;
        if nu != task.act_dim {
            return Err(SimError::ModelMismatch {
                xml: task.xml,
                task: name.as_str(),
                what: "actuators",
                found: nu,
                expected: task.act_dim,
            });
        }
        let progress_body = match task.progress {
            Progress::BodyX { body } => {
                model
                    .name_to_id(MjtObjBase::mjOBJ_BODY, body)
                    .ok_or(SimError::MissingBody {
                        xml: task.xml,
                        body,
                    })?
            }
            _ => 0,
        };
        let body_mass = model.body_mass().to_vec();
        let total_mass = body_mass.iter().sum();
        let (action_low, action_high) = model
            .actuator_ctrlrange()
            .iter()
            .map(|r| (r[0], r[1]))
            .unzip();
        let model = Arc::new(model);
        // A new mjData is a reset one (`mj_makeData` ends with `mj_resetData`).
        let fresh = MjData::new(model.clone());
        let init_qpos = fresh.qpos().to_vec();
        let reset_state = fresh.state(INTEGRATION_STATE).into_vec();
        Ok(Arc::new(TaskModel {
            task,
            model,
            dt,
            nq,
            nv,
            init_qpos,
            reset_state,
            action_low,
            action_high,
            progress_body,
            body_mass,
            total_mass,
        }))
    }

    /// What `mj_resetData` does to `data` for everything after it: it writes the integration
    /// state that call leaves (nothing else in an mjData reaches a later step, which a
    /// restored snapshot relies on too) and zeroes the constraint forces a task's
    /// observation reads before any step has computed them. The same observations and
    /// physics bit for bit (tested against Gymnasium's sequence), without zeroing the whole
    /// mjData buffer, which on a batch's cold copies cost ~10 µs a reset: a quarter of an
    /// InvertedPendulum batch's time under random actions (an episode every ~6 steps).
    pub fn reset_data(&self, data: &mut MjData<Arc<MjModel>>) {
        data.set_state(&self.reset_state, INTEGRATION_STATE)
            .expect("the reset state is of this model");
        if self.task.observes_constraint_forces {
            data.cacc_mut().fill([0.0; 6]);
            data.cfrc_int_mut().fill([0.0; 6]);
            data.cfrc_ext_mut().fill([0.0; 6]);
        }
    }
}
