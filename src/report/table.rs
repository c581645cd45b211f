//! Table 1's layout: rows Δ × algorithm × protocol (the delay-free reference first; runs of
//! another implementation apart), a column per task,
//! mean ± std over seeds of each run's final evaluation, the best of each Δ block marked, the
//! paper's published numbers beside ours.
use std::collections::BTreeSet;

use super::results::{RunResult, Variant, entries};
use super::stats::mean_std;
use crate::algos::paper_name;
use crate::tasks::TaskName;

/// The paper's Table 1 (its arXiv LaTeX source, table `result-table`:
/// MuJoCo v3 tasks and InvertedPendulum-v2, 1M steps, 5 seeds), transcribed as
/// `delay,algorithm,task,mean,std,marked_best` with Δ = 0 for delay-free SAC.
const PAPER_TABLE1: &str = include_str!("paper_table1.csv");

/// One published cell.
#[derive(Debug, Clone, PartialEq)]
pub struct PaperCell {
    pub delay: usize,
    pub algorithm: String,
    pub task: TaskName,
    pub mean: f64,
    pub std: f64,
    /// Whether the paper highlights it as the best of its Δ.
    pub best: bool,
}

/// The paper's Table 1.
pub fn paper_table1() -> Vec<PaperCell> {
    PAPER_TABLE1
        .lines()
        .skip(1)
        .map(|line| {
            let f: Vec<&str> = line.split(',').collect();
            PaperCell {
                delay: f[0].parse().expect("shipped data"),
                algorithm: f[1].to_string(),
                task: f[2].parse().expect("shipped data"),
                mean: f[3].parse().expect("shipped data"),
                std: f[4].parse().expect("shipped data"),
                best: f[5] == "true",
            }
        })
        .collect()
}

/// Our cell: the final evaluations of a (Δ, algorithm, task)'s seeds.
#[derive(Debug, Clone, PartialEq)]
pub struct OurCell {
    pub mean: f64,
    pub std: f64,
    pub seeds: usize,
    /// The earliest final-evaluation step among the seeds.
    pub final_step: u64,
    /// The highest mean of its Δ block (Δ > 0) and task.
    pub best: bool,
    /// Whether its runs differ in more than their seeds (other settings pooled: marked †).
    pub mixed: bool,
}

#[derive(Debug, Clone)]
pub struct Table {
    pub tasks: Vec<TaskName>,
    /// `(Δ, algorithm, variant, per task: ours, the paper's)`.
    pub rows: Rows,
}

/// The table of the runs under fixed delays without actuator noise.
pub fn table1(runs: &[RunResult]) -> Table {
    let runs: Vec<&RunResult> = runs.iter().filter(|r| r.condition.is_table1()).collect();
    let tasks: Vec<TaskName> = TaskName::ALL
        .into_iter()
        .filter(|t| runs.iter().any(|r| r.task == *t))
        .collect();
    let delays: BTreeSet<usize> = runs.iter().map(|r| r.condition.delay).collect();
    let paper = paper_table1();
    let mut rows = Vec::new();
    for &delay in &delays {
        for (algorithm, variant) in entries(runs.iter().copied()) {
            let cells: Vec<_> = tasks
                .iter()
                .map(|&task| {
                    let cell: Vec<&&RunResult> = runs
                        .iter()
                        .filter(|r| {
                            r.condition.delay == delay
                                && r.is(algorithm, &variant)
                                && r.task == task
                        })
                        .collect();
                    let finals: Vec<(u64, f64)> = cell.iter().map(|r| r.final_eval()).collect();
                    let settings: BTreeSet<&str> =
                        cell.iter().map(|r| r.setting.as_str()).collect();
                    let ours = (!finals.is_empty()).then(|| {
                        let (mean, std) = mean_std(&finals.iter().map(|f| f.1).collect::<Vec<_>>());
                        OurCell {
                            mean,
                            std,
                            seeds: finals.len(),
                            final_step: finals.iter().map(|f| f.0).min().unwrap_or(0),
                            best: false,
                            mixed: settings.len() > 1,
                        }
                    });
                    let published = paper
                        .iter()
                        .find(|p| p.delay == delay && p.algorithm == algorithm && p.task == task)
                        .cloned();
                    (ours, published)
                })
                .collect();
            if cells.iter().any(|c| c.0.is_some()) {
                rows.push((delay, algorithm, variant, cells));
            }
        }
    }
    mark_best(&mut rows, tasks.len());
    Table { tasks, rows }
}

pub type Rows = Vec<(
    usize,
    &'static str,
    Variant,
    Vec<(Option<OurCell>, Option<PaperCell>)>,
)>;

fn mark_best(rows: &mut Rows, tasks: usize) {
    let delays: BTreeSet<usize> = rows.iter().map(|r| r.0).filter(|&d| d > 0).collect();
    for delay in delays {
        for t in 0..tasks {
            let best = rows
                .iter()
                .enumerate()
                .filter(|(_, r)| r.0 == delay)
                .filter_map(|(i, r)| r.3[t].0.as_ref().map(|c| (i, c.mean)))
                .max_by(|a, b| a.1.total_cmp(&b.1));
            if let Some((i, _)) = best
                && let Some(cell) = rows[i].3[t].0.as_mut()
            {
                cell.best = true;
            }
        }
    }
}

fn delay_label(delay: usize) -> String {
    if delay == 0 {
        "–".into()
    } else {
        delay.to_string()
    }
}

impl Table {
    pub fn markdown(&self) -> String {
        let mut out = String::from("| Δ | algorithm | protocol |");
        for task in &self.tasks {
            out += &format!(" {task} (ours) | {task} (paper) |");
        }
        out += "\n|---|---|---|";
        out += &"---:|---:|".repeat(self.tasks.len());
        out += "\n";
        for (delay, algorithm, variant, cells) in &self.rows {
            out += &format!(
                "| {} | {} | {} |",
                delay_label(*delay),
                paper_name(algorithm),
                variant.label()
            );
            for (ours, paper) in cells {
                let ours = ours.as_ref().map_or("".into(), |c| {
                    let text = format!(
                        "{:.1} ± {:.1} ({}){}",
                        c.mean,
                        c.std,
                        c.seeds,
                        if c.mixed { " †" } else { "" }
                    );
                    if c.best { format!("**{text}**") } else { text }
                });
                let paper = paper.as_ref().map_or("".into(), |p| {
                    let text = format!("{:.1} ± {}", p.mean, p.std);
                    if p.best { format!("**{text}**") } else { text }
                });
                out += &format!(" {ours} | {paper} |");
            }
            out += "\n";
        }
        out
    }

    pub fn latex(&self) -> String {
        let mut out = format!(
            "% dhrl report: mean ± std over seeds (their number in brackets) of the final\n\
             % evaluation; the paper's Table 1 beside; the best of each Δ in bold.\n\
             \\begin{{tabular}}{{lll{}}}\n\\hline\n$\\Delta$ & Algorithm & Protocol",
            "rr".repeat(self.tasks.len())
        );
        for task in &self.tasks {
            out += &format!(" & \\multicolumn{{2}}{{c}}{{{}}}", task.gymnasium_id());
        }
        out += " \\\\\n & &";
        out += &" & ours & paper".repeat(self.tasks.len());
        out += " \\\\\n\\hline\n";
        let mut previous = None;
        for (delay, algorithm, variant, cells) in &self.rows {
            if previous.is_some() && previous != Some(*delay) {
                out += "\\hline\n";
            }
            previous = Some(*delay);
            let name = latex_name(paper_name(algorithm));
            out += &format!(
                "{} & {name} & {}",
                latex_text(&delay_label(*delay)),
                latex_text(&variant.label())
            );
            for (ours, paper) in cells {
                let bold = |text: String, best: bool| {
                    if best {
                        format!("\\textbf{{{text}}}")
                    } else {
                        text
                    }
                };
                let ours = ours.as_ref().map_or("".into(), |c| {
                    bold(
                        format!(
                            "${:.1}_{{\\pm {:.1}}}$ ({}){}",
                            c.mean,
                            c.std,
                            c.seeds,
                            if c.mixed { "$^\\dagger$" } else { "" }
                        ),
                        c.best,
                    )
                });
                let paper = paper.as_ref().map_or("".into(), |p| {
                    bold(format!("${:.1}_{{\\pm {}}}$", p.mean, p.std), p.best)
                });
                out += &format!(" & {ours} & {paper}");
            }
            out += " \\\\\n";
        }
        out += "\\hline\n\\end{tabular}\n";
        out
    }

    pub fn csv(&self) -> String {
        let mut out = String::from(
            "delay,algorithm,protocol,implementation,task,seeds,mean,std,final_step,best,mixed,paper_mean,paper_std\n",
        );
        for (delay, algorithm, variant, cells) in &self.rows {
            let variant = variant.csv_fields();
            for (task, (ours, paper)) in self.tasks.iter().zip(cells) {
                let Some(c) = ours else { continue };
                let (pm, ps) = paper.as_ref().map_or((String::new(), String::new()), |p| {
                    (p.mean.to_string(), p.std.to_string())
                });
                out += &format!(
                    "{delay},{algorithm},{variant},{task},{},{:.3},{:.3},{},{},{},{pm},{ps}\n",
                    c.seeds, c.mean, c.std, c.final_step, c.best, c.mixed
                );
            }
        }
        out
    }

    /// Whether some cell pools runs of other settings than their seeds.
    pub fn mixed(&self) -> bool {
        self.rows
            .iter()
            .any(|r| r.3.iter().any(|c| c.0.as_ref().is_some_and(|o| o.mixed)))
    }

    /// The distinct final-evaluation steps of the table's cells.
    pub fn final_steps(&self) -> BTreeSet<u64> {
        self.rows
            .iter()
            .flat_map(|r| {
                r.3.iter()
                    .filter_map(|c| c.0.as_ref().map(|o| o.final_step))
            })
            .collect()
    }
}

/// Text as LaTeX typesets it literally: its special characters escaped (an implementation's
/// label is a user's own text, from implementation.txt).
fn latex_text(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '\\' => out += "\\textbackslash{}",
            '~' => out += "\\textasciitilde{}",
            '^' => out += "\\textasciicircum{}",
            '&' | '%' | '$' | '#' | '_' | '{' | '}' => {
                out.push('\\');
                out.push(c);
            }
            '–' => out += "--",
            _ => out.push(c),
        }
    }
    out
}

/// A paper name in LaTeX: the paper sets the "2" of "D2" as a superscript.
fn latex_name(name: &str) -> String {
    name.replacen("D2", "D$^2$", 1)
}

#[cfg(test)]
mod tests {
    use super::latex_text;

    /// An implementation's own label reaches the LaTeX table literally: its special characters
    /// escaped, a plain label unchanged.
    #[test]
    fn labels_are_escaped_for_latex() {
        assert_eq!(
            latex_text("authors (authors' code, JongsooLee/DHRL 296ac7b)"),
            "authors (authors' code, JongsooLee/DHRL 296ac7b)"
        );
        assert_eq!(
            latex_text(r"my_fork #2 & 50% {x} $\alpha$ ~^"),
            r"my\_fork \#2 \& 50\% \{x\} \$\textbackslash{}alpha\$ \textasciitilde{}\textasciicircum{}"
        );
    }
}
