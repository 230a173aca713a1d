//! Which of Open MPI's point-to-point layers a rank starts with, where the user has not said.
//!
//! Open MPI 4.1 as Debian builds it first tries UCX, the layer for RDMA networks (InfiniBand,
//! RoCE, Omni-Path through the `cm` layer and its PSM and libfabric modules), and falls back to
//! its own TCP and shared-memory layer (`ob1`) when it finds no such device (Debian's site file
//! already leaves UCX out). The tries cost each rank about 0.2 s of waiting in `MPI_Init`
//! (measured here: 0.25 s against 0.06 s with `OMPI_MCA_pml=ob1`, 3 ranks, Open MPI 4.1.4), on
//! every job, to arrive at the layer it would have chosen anyway. So on a host without an RDMA device a rank asks for
//! `ob1` from the start. A host with one is left to Open MPI, as is any choice the user or the
//! site made (the environment, `mpirun --mca`, or an MCA parameter file).

use std::path::Path;

/// The MCA parameter that names the point-to-point layer.
pub const PML_VARIABLE: &str = "OMPI_MCA_pml";

/// What a host offers, for the choice.
pub struct HostTransport<'a> {
    /// Started by Open MPI's mpirun (its rank variables are set).
    pub open_mpi: bool,
    /// `OMPI_MCA_pml` as the rank's environment has it (mpirun --mca sets it there too).
    pub pml_variable: Option<&'a str>,
    /// The text of the MCA parameter files that exist (the site's and the user's).
    pub parameter_files: &'a [String],
    /// RDMA devices the kernel lists (`/sys/class/infiniband`: InfiniBand and RoCE alike).
    pub rdma_devices: usize,
}

/// The layer to ask for, or None to leave the choice to Open MPI. A setting that names layers
/// is a choice and is kept; one that only excludes some (`^ucx`, as Debian's site file has it)
/// leaves Open MPI to try the rest, and `ob1` may be asked for unless it is excluded too.
pub fn pml_to_ask_for(host: &HostTransport<'_>) -> Option<&'static str> {
    let from_files = host.parameter_files.iter().flat_map(|text| {
        text.lines().filter_map(|line| {
            let (key, value) = line.split('#').next().unwrap_or("").split_once('=')?;
            (key.trim() == "pml").then(|| value.trim().to_string())
        })
    });
    let settings: Vec<String> = from_files.chain(host.pml_variable.map(str::to_string)).collect();
    let leaves_ob1 = |setting: &String| {
        setting
            .strip_prefix('^')
            .is_some_and(|excluded| excluded.split(',').all(|layer| layer.trim() != "ob1"))
    };
    (host.open_mpi && host.rdma_devices == 0 && settings.iter().all(leaves_ob1)).then_some("ob1")
}

/// This host as it is: the environment, the parameter files Open MPI reads, the RDMA devices.
pub fn this_host_asks_for() -> Option<&'static str> {
    let home = std::env::var_os("HOME").map(|h| Path::new(&h).join(".openmpi/mca-params.conf"));
    let files: Vec<String> = [
        Some(Path::new("/etc/openmpi/openmpi-mca-params.conf").to_path_buf()),
        home,
    ]
    .into_iter()
    .flatten()
    .filter_map(|path| std::fs::read_to_string(path).ok())
    .collect();
    let pml = std::env::var(PML_VARIABLE).ok();
    let rdma_devices = std::fs::read_dir("/sys/class/infiniband").map_or(0, |dir| dir.count());
    pml_to_ask_for(&HostTransport {
        open_mpi: std::env::var_os("OMPI_COMM_WORLD_SIZE").is_some(),
        pml_variable: pml.as_deref(),
        parameter_files: &files,
        rdma_devices,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn host<'a>(pml: Option<&'a str>, files: &'a [String], rdma: usize) -> HostTransport<'a> {
        HostTransport {
            open_mpi: true,
            pml_variable: pml,
            parameter_files: files,
            rdma_devices: rdma,
        }
    }

    #[test]
    fn a_host_without_rdma_asks_for_ob1_unless_someone_chose() {
        assert_eq!(pml_to_ask_for(&host(None, &[], 0)), Some("ob1"));
        assert_eq!(pml_to_ask_for(&host(Some("ucx"), &[], 0)), None);
        assert_eq!(pml_to_ask_for(&host(None, &[], 1)), None);
        let site = ["# the site's\n  pml = ucx\n".to_string()];
        assert_eq!(pml_to_ask_for(&host(None, &site, 0)), None);
        let other = ["btl = self,vader,tcp\n# pml = ucx\npml_ucx_verbose = 1\n".to_string()];
        assert_eq!(pml_to_ask_for(&host(None, &other, 0)), Some("ob1"));
        // Debian's site file excludes UCX: the rest is still Open MPI's to try, ob1 among them.
        let debian = ["mtl = ^ofi\npml = ^ucx\nosc = ^ucx,pt2pt\n".to_string()];
        assert_eq!(pml_to_ask_for(&host(None, &debian, 0)), Some("ob1"));
        assert_eq!(pml_to_ask_for(&host(Some("^cm, ob1"), &debian, 0)), None);
        assert_eq!(pml_to_ask_for(&host(Some("^cm"), &debian, 0)), Some("ob1"));
        let not_open_mpi = HostTransport {
            open_mpi: false,
            ..host(None, &[], 0)
        };
        assert_eq!(pml_to_ask_for(&not_open_mpi), None);
    }
}
