//! Steps scripted as environments: what each task concludes, and what it refuses.

use super::*;

/// The variables srun sets for task `rank` of a `tasks`-task step on `nodes`.
fn step_env(rank: u32, tasks: u32, nodes: &str) -> Env {
    [
        ("SLURM_PROCID", rank.to_string()),
        ("SLURM_STEP_NUM_TASKS", tasks.to_string()),
        ("SLURM_NTASKS", tasks.to_string()),
        ("SLURM_STEP_NODELIST", nodes.to_string()),
        ("SLURM_JOB_NODELIST", nodes.to_string()),
        ("SLURM_JOB_ID", "123456".to_string()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

fn with(mut env: Env, name: &str, value: &str) -> Env {
    env.insert(name.to_string(), value.to_string());
    env
}

fn without(mut env: Env, name: &str) -> Env {
    env.remove(name);
    env
}

fn step(env: &Env) -> Step {
    Step::from_env(env, &Overrides::default()).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn rank_zero_owns_and_waits_for_the_others() {
    let owner = step(&with(step_env(0, 4, "n[01-04]"), "SLURMD_NODENAME", "n01"));
    assert_eq!(owner.role(), Role::Owner { peers: 3 });
    assert_eq!(owner.owner, "n01");
    assert_eq!(owner.nodes, ["n01", "n02", "n03", "n04"]);
    // 20000 + 10 * (123456 mod 2000) + step 0: no SLURM_STEP_ID is step 0.
    assert_eq!(owner.port, 34560);
    assert_eq!(owner.cpus_per_task, None);
}

#[test]
fn every_rank_agrees_on_the_owner_and_port() {
    let env = |rank| {
        with(
            step_env(rank, 3, "rack-2-n[7-8],login"),
            "SLURMD_NODENAME",
            "x",
        )
    };
    let steps: Vec<Step> = (1..3).map(|rank| step(&env(rank))).collect();
    for (i, s) in steps.iter().enumerate() {
        assert_eq!(
            s.role(),
            Role::Peer {
                index: i as u32 + 1
            }
        );
        assert_eq!(s.owner, "rack-2-n7");
        assert_eq!(s.port, steps[0].port);
    }
}

#[test]
fn the_step_is_preferred_to_the_job() {
    // A step on part of the job's allocation: its own task count and nodes win.
    let env = with(
        with(step_env(1, 2, "n[3-4]"), "SLURM_NTASKS", "16"),
        "SLURM_JOB_NODELIST",
        "n[1-8]",
    );
    let s = step(&env);
    assert_eq!((s.tasks, s.owner.as_str()), (2, "n3"));
    // Without the step's variables, the job's are used.
    let env = without(without(env, "SLURM_STEP_NUM_TASKS"), "SLURM_STEP_NODELIST");
    let s = step(&env);
    assert_eq!((s.tasks, s.owner.as_str()), (16, "n1"));
}

#[test]
fn cpus_per_task_and_old_job_id_names_are_read() {
    let env = with(step_env(1, 2, "a,b"), "SLURM_CPUS_PER_TASK", "12");
    assert_eq!(step(&env).cpus_per_task, Some(12));
    let env = with(without(env, "SLURM_JOB_ID"), "SLURM_JOBID", "7");
    assert_eq!(step(&env).port, 20070);
    let env = with(env, "SLURM_CPUS_PER_TASK", "0");
    assert!(matches!(
        Step::from_env(&env, &Overrides::default()),
        Err(SlurmError::Invalid {
            name: "SLURM_CPUS_PER_TASK",
            ..
        })
    ));
}

#[test]
fn default_ports_stay_in_their_range() {
    for job in [
        0,
        1,
        1_999,
        2_000,
        19_999,
        20_000,
        39_999,
        1 << 40,
        u64::MAX,
    ] {
        for step in [0, 1, 9, 10, 4_294_967_290, u64::MAX] {
            let port = default_port(job, step);
            assert!((20000..40000).contains(&port), "{job}.{step} -> {port}");
        }
    }
    assert_eq!(default_port(0, 0), 20000);
    assert_eq!(default_port(1_999, 9), 39999);
}

#[test]
fn steps_of_one_job_and_nearby_jobs_get_ports_of_their_own() {
    // Every step 0..10 of every job in a window of 2000 consecutive ids: all distinct.
    let mut seen = std::collections::BTreeMap::new();
    for job in 123_000..125_000 {
        for step in 0..STEPS_PER_JOB {
            let port = default_port(job, step);
            if let Some(other) = seen.insert(port, (job, step)) {
                panic!("{job}.{step} and {other:?} share port {port}");
            }
        }
    }
    assert_eq!(seen.len(), 20000);
    // The eleventh step of a job reuses the first's port: the block is ten wide.
    assert_eq!(default_port(7, 10), default_port(7, 0));
    assert_eq!(default_port(7, 0) + 3, default_port(7, 3));
}

#[test]
fn the_step_id_picks_the_port_within_the_job_block() {
    let env = with(step_env(1, 2, "n[1-2]"), "SLURM_STEP_ID", "3");
    assert_eq!(step(&env).port, default_port(123456, 3));
    assert_eq!(step(&env).port, 34563);
    // The old name is read where the new one is absent.
    let env = with(without(env, "SLURM_STEP_ID"), "SLURM_STEPID", "2");
    assert_eq!(step(&env).port, 34562);
    // Every task of a step agrees: the id is the step's, not the task's.
    let env = |rank| with(step_env(rank, 3, "n[1-3]"), "SLURM_STEP_ID", "1");
    assert_eq!(step(&env(1)).port, step(&env(2)).port);
    let error = Step::from_env(
        &with(step_env(1, 2, "n[1-2]"), "SLURM_STEP_ID", "batch"),
        &Overrides::default(),
    )
    .unwrap_err();
    assert!(matches!(
        error,
        SlurmError::Invalid {
            name: "SLURM_STEP_ID",
            ..
        }
    ));
    // --port wins over both ids.
    let overrides = Overrides {
        owner: None,
        port: Some(4433),
    };
    let env = with(step_env(1, 2, "n[1-2]"), "SLURM_STEP_ID", "1");
    assert_eq!(Step::from_env(&env, &overrides).unwrap().port, 4433);
}

#[test]
fn outside_slurm_every_missing_variable_is_named() {
    let error = Step::from_env(&Env::new(), &Overrides::default()).unwrap_err();
    let message = error.to_string();
    for name in [
        "SLURM_PROCID",
        "SLURM_STEP_NUM_TASKS",
        "SLURM_STEP_NODELIST",
        "SLURM_JOB_ID",
        "srun",
    ] {
        assert!(message.contains(name), "{message}");
    }
    // An empty variable is as good as none.
    let env = with(step_env(0, 2, "n1"), "SLURM_PROCID", "");
    assert_eq!(
        Step::from_env(&env, &Overrides::default()),
        Err(SlurmError::Missing(vec!["SLURM_PROCID"]))
    );
}

#[test]
fn overrides_stand_in_for_the_node_list_and_job_id() {
    let env = without(
        without(
            without(step_env(2, 3, "n1"), "SLURM_STEP_NODELIST"),
            "SLURM_JOB_NODELIST",
        ),
        "SLURM_JOB_ID",
    );
    assert!(matches!(
        Step::from_env(&env, &Overrides::default()),
        Err(SlurmError::Missing(names)) if names.len() == 2
    ));
    let overrides = Overrides {
        owner: Some("head.example.org".into()),
        port: Some(4433),
    };
    let s = Step::from_env(&env, &overrides).unwrap();
    assert_eq!((s.owner.as_str(), s.port), ("head.example.org", 4433));
}

#[test]
fn bad_numbers_name_the_variable() {
    for (name, value) in [
        ("SLURM_PROCID", "one"),
        ("SLURM_STEP_NUM_TASKS", "-3"),
        ("SLURM_JOB_ID", "12a"),
    ] {
        let error = Step::from_env(
            &with(step_env(0, 2, "n1"), name, value),
            &Overrides::default(),
        )
        .unwrap_err();
        let message = error.to_string();
        assert!(
            message.contains(name) && message.contains(value),
            "{message}"
        );
    }
}

#[test]
fn ranks_and_task_counts_must_make_a_cluster() {
    assert_eq!(
        Step::from_env(&step_env(0, 1, "n1"), &Overrides::default()),
        Err(SlurmError::TooFewTasks(1))
    );
    assert_eq!(
        Step::from_env(&step_env(3, 3, "n[1-3]"), &Overrides::default()),
        Err(SlurmError::RankOutOfRange { rank: 3, tasks: 3 })
    );
}

#[test]
fn a_malformed_node_list_is_refused_with_the_variable_and_value() {
    let error = Step::from_env(&step_env(1, 2, "n[1-2"), &Overrides::default()).unwrap_err();
    assert_eq!(
        error,
        SlurmError::Hostlist {
            name: "SLURM_STEP_NODELIST",
            value: "n[1-2".into(),
            source: HostlistError::Unclosed { at: 1 },
        }
    );
    assert!(error.to_string().contains("never closed"));
}

#[test]
fn rank_zero_refuses_to_own_from_a_node_peers_will_not_dial() {
    let env = with(step_env(0, 2, "n[1-2]"), "SLURMD_NODENAME", "n2");
    assert_eq!(
        Step::from_env(&env, &Overrides::default()),
        Err(SlurmError::OwnerElsewhere {
            here: "n2".into(),
            first: "n1".into()
        })
    );
    // Peers cannot check (they are anywhere), and naming the owner settles it.
    let peer = with(step_env(1, 2, "n[1-2]"), "SLURMD_NODENAME", "n1");
    assert_eq!(step(&peer).owner, "n1");
    let named = Overrides {
        owner: Some("n2".into()),
        port: None,
    };
    assert_eq!(Step::from_env(&env, &named).unwrap().owner, "n2");
}

#[test]
fn arbitrary_layouts_need_the_owner_named() {
    for layout in ["arbitrary", "arbitrary:cyclic"] {
        let env = with(step_env(1, 2, "n[1-2]"), "SLURM_DISTRIBUTION", layout);
        assert_eq!(
            Step::from_env(&env, &Overrides::default()),
            Err(SlurmError::ArbitraryLayout(layout.into()))
        );
    }
    for layout in [
        "block",
        "cyclic",
        "plane",
        "block:cyclic",
        "cyclic:block,Pack",
    ] {
        let env = with(step_env(1, 2, "n[1-2]"), "SLURM_DISTRIBUTION", layout);
        assert_eq!(step(&env).owner, "n1", "{layout}");
    }
}

/// Peers dial the owner's IPv4 address; a host with only IPv6 ones is refused, saying why.
/// Address literals only: a test must not depend on a resolver.
#[test]
fn peers_dial_the_owner_over_ipv4() {
    let address = owner_address("127.0.0.1", 20_017).unwrap();
    assert_eq!(
        address,
        std::net::SocketAddr::from(([127, 0, 0, 1], 20_017))
    );
    let error = owner_address("::1", 20_017).unwrap_err();
    assert!(matches!(error, OwnerAddressError::NoIpv4 { .. }), "{error}");
    assert!(
        error.to_string().ends_with("name another with --owner"),
        "{error}"
    );
}
