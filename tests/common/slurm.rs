//! A real one-node Slurm for the tests: munged, slurmctld and slurmd (Debian's `slurm-wlm` and
//! `munge`) started as root on localhost with every file in a temporary folder, and stopped
//! when dropped. `scripts/test.sh` installs the packages and sets `DHRL_REQUIRE_SLURM=1`, so
//! that a missing Slurm fails there instead of skipping.
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

pub struct Slurm {
    folder: tempfile::TempDir,
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn run(program: &str, args: &[&str]) -> Output {
    Command::new(program)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("{program}: {e}"))
}

fn succeeded(program: &str, args: &[&str], out: &Output) {
    assert!(
        out.status.success(),
        "{program} {args:?}: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

impl Slurm {
    /// Starts a one-node cluster, or returns `None` (saying why) where Slurm or root is
    /// missing and `DHRL_REQUIRE_SLURM` is not `1`.
    pub fn start(test: &str) -> Option<Slurm> {
        let missing = ["munged", "slurmctld", "slurmd", "sbatch", "scontrol"]
            .into_iter()
            .filter(|p| {
                Command::new("which")
                    .arg(p)
                    .output()
                    .map_or(true, |o| !o.status.success())
            })
            .collect::<Vec<_>>();
        let root = run("id", &["-u"]).stdout == b"0\n";
        if !missing.is_empty() || !root {
            let why = format!(
                "{test}: a one-node Slurm needs root and Debian's slurm-wlm and munge (missing: \
                 {missing:?}, root: {root})"
            );
            assert!(
                std::env::var("DHRL_REQUIRE_SLURM").as_deref() != Ok("1"),
                "{why}, but DHRL_REQUIRE_SLURM=1"
            );
            eprintln!("{why}: skipped");
            return None;
        }
        let folder = tempfile::Builder::new()
            .prefix("dhrl-slurm")
            .tempdir()
            .unwrap();
        let slurm = Slurm { folder };
        let dir = slurm.folder.path();
        for sub in ["munge", "state", "spool", "log"] {
            std::fs::create_dir(dir.join(sub)).unwrap();
        }
        std::fs::write(dir.join("munge/key"), rand_key()).unwrap();
        let chmod = |mode: &str, path: &Path| {
            succeeded("chmod", &[], &run("chmod", &[mode, path.to_str().unwrap()]))
        };
        chmod("0400", &dir.join("munge/key"));
        chmod("0755", dir);
        let path = |name: &str| dir.join(name).display().to_string();
        let munged = [
            "--force".to_string(),
            format!("--key-file={}", path("munge/key")),
            format!("--socket={}", path("munge/socket")),
            format!("--pid-file={}", path("munge/pid")),
            format!("--log-file={}", path("munge/log")),
            format!("--seed-file={}", path("munge/seed")),
        ];
        let munged: Vec<&str> = munged.iter().map(String::as_str).collect();
        succeeded("munged", &munged, &run("munged", &munged));
        let host = String::from_utf8(run("hostname", &["-s"]).stdout).unwrap();
        let host = host.trim();
        let cpus = std::thread::available_parallelism().unwrap().get();
        let conf = format!(
            "ClusterName=dhrltest\n\
             SlurmctldHost={host}(127.0.0.1)\n\
             SlurmUser=root\nSlurmdUser=root\n\
             AuthType=auth/munge\nCredType=cred/munge\nAuthInfo=socket={socket}\n\
             SlurmctldPort={ctld_port}\nSlurmdPort={d_port}\n\
             StateSaveLocation={state}\nSlurmdSpoolDir={spool}\n\
             SlurmctldPidFile={dir}/slurmctld.pid\nSlurmdPidFile={dir}/slurmd.pid\n\
             SlurmctldLogFile={dir}/log/slurmctld.log\nSlurmdLogFile={dir}/log/slurmd.log\n\
             ProctrackType=proctrack/linuxproc\nTaskPlugin=task/none\n\
             SelectType=select/cons_tres\nSelectTypeParameters=CR_Core\n\
             ReturnToService=2\nMpiDefault=none\nKillWait=60\n\
             JobAcctGatherType=jobacct_gather/none\nAccountingStorageType=accounting_storage/none\n\
             NodeName={host} NodeAddr=127.0.0.1 CPUs={cpus} State=UNKNOWN\n\
             PartitionName=test Nodes={host} Default=YES MaxTime=INFINITE State=UP\n",
            socket = path("munge/socket"),
            ctld_port = free_port(),
            d_port = free_port(),
            state = path("state"),
            spool = path("spool"),
            dir = dir.display(),
        );
        std::fs::write(dir.join("slurm.conf"), conf).unwrap();
        let conf = path("slurm.conf");
        for daemon in ["slurmctld", "slurmd"] {
            let out = Command::new(daemon)
                .args(["-f", &conf])
                .env("SLURM_CONF", &conf)
                .output()
                .unwrap();
            succeeded(daemon, &[], &out);
        }
        let start = Instant::now();
        loop {
            let out = slurm.command("sinfo", &["-h", "-o", "%t"]);
            if out.status.success() && String::from_utf8_lossy(&out.stdout).trim() == "idle" {
                break;
            }
            assert!(
                start.elapsed() < Duration::from_secs(60),
                "the node is not idle after 60 s: {}{}\n{}",
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr),
                slurm.logs()
            );
            std::thread::sleep(Duration::from_millis(200));
        }
        Some(slurm)
    }

    pub fn conf(&self) -> PathBuf {
        self.folder.path().join("slurm.conf")
    }

    /// A Slurm command (`squeue`, `scontrol`, …) against this cluster.
    pub fn command(&self, program: &str, args: &[&str]) -> Output {
        Command::new(program)
            .args(args)
            .env("SLURM_CONF", self.conf())
            .output()
            .unwrap()
    }

    /// The daemons' logs, for a failure message.
    pub fn logs(&self) -> String {
        ["log/slurmctld.log", "log/slurmd.log"]
            .iter()
            .map(|f| {
                let text = std::fs::read_to_string(self.folder.path().join(f)).unwrap_or_default();
                let tail: Vec<&str> = text.lines().rev().take(30).collect();
                format!(
                    "--- {f} (last lines)\n{}",
                    tail.into_iter().rev().collect::<Vec<_>>().join("\n")
                )
            })
            .collect::<Vec<_>>()
            .join("\n")
    }

    fn pid(&self, file: &str) -> Option<String> {
        std::fs::read_to_string(self.folder.path().join(file))
            .ok()
            .map(|p| p.trim().to_string())
    }
}

impl Drop for Slurm {
    fn drop(&mut self) {
        // `scontrol shutdown` stops slurmctld and slurmd; munged by its pid file. Each daemon
        // is waited for (by its pid), so that the folder goes only after them.
        let pids: Vec<String> = ["slurmctld.pid", "slurmd.pid", "munge/pid"]
            .iter()
            .filter_map(|f| self.pid(f))
            .collect();
        let _ = self.command("scontrol", &["shutdown"]);
        std::thread::sleep(Duration::from_secs(1));
        if let Some(munged) = self.pid("munge/pid") {
            let _ = run("kill", &[&munged]);
        }
        let start = Instant::now();
        while start.elapsed() < Duration::from_secs(20) && pids.iter().any(|p| alive(p)) {
            std::thread::sleep(Duration::from_millis(100));
        }
        for p in &pids {
            if alive(p) {
                let _ = run("kill", &["-9", p]);
            }
        }
    }
}

/// Whether process `pid` runs (a zombie left to a container's init does not).
fn alive(pid: &str) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|stat| {
        stat.rsplit_once(") ")
            .is_some_and(|(_, rest)| !rest.starts_with('Z'))
    })
}

fn rand_key() -> Vec<u8> {
    let mut key = vec![0u8; 1024];
    use std::io::Read;
    std::fs::File::open("/dev/urandom")
        .unwrap()
        .read_exact(&mut key)
        .unwrap();
    key
}
