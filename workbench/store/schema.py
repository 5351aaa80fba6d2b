"""The store's schema (CONVENTIONS.md, Store; Wan & Harada Section IV, Fig. 4 and Fig. 5).

The ten tables of the paper keep their names and columns (lowercase). Poses are `DOUBLE[16]` row-major
4x4 transforms, points and normals `DOUBLE[3]`, distances in metres, angles in radians.

Paper tables
- object(idobject, name, ...): one row per object; extra columns keep the scaled mesh (vertices, faces),
  its digest, scale, source path, centre of mass and how it was computed (volume or area).
- robot(idrobot, name, ...): what rebuilds the kinematic chain without the library: urdf text (with a link named
  tcp_frame fixed to tip_frame at the mount where the robot's own URDF lacks it), tcp_frame,
  tip_frame, mount (tip to TCP), base (base pose in the world), joint_names (order of stored joint vectors),
  locked (JSON {joint: value} for URDF joints outside joint_names that are not at 0, e.g. a humanoid's other arm
  tucked away) and drop_geometry (link-name prefixes whose collision geometry is replaced by the planning gripper).
  Extra: allowed_pairs (JSON: the link pairs exempt from self-collision checks, with their reason: rigid,
  adjacent, srdf, never, always; the planning gripper is the links gripper_hand and gripper_fingers).
- freeairgrip: grasps in the object frame; rotmat is the TCP pose in the object frame.
  Extra: idparamset, idgripper, idfacet0/idfacet1 (facet ids of the run), idcontactpair, rotation (rad about y),
  padoffset0/padoffset1 (`DOUBLE[2]`: where each contact lies on its pad, along the TCP's x and z from the pad's
  centre in pad half sizes, 1 at an edge) and robustness (1 minus the larger offset, 0 at an edge; NULL in stores
  written before them).
- freetabletopplacement: rotmat is the object in the table frame, centre of mass above the origin, lowest
  point on z = 0. Extra: idparamset, stability (paper Section VI measure), support (support polygon, `DOUBLE[3][]`),
  probability (quasi-static chance that a part dropped at random rests on it) and rocking (true when a small tilt
  rolls the part on onto the next hull face, as on a faceted round side); both NULL in stores written before them.
- freetabletopgrip: free-air grasps kept at a free placement; rotmat is the TCP in the table frame.
- angle(idangle, value): rotations about world z in radians.
- tabletopplacements: rotmat is the object in the world; tabletopposition the (x, y, z) of the placement.
- tabletopgrips: rotmat is the TCP in the world.
- ikret(idikret, handx, worldz, worlda): retraction distances in metres (worlda: the held object lifted straight
  up, as in the paper's reference implementation).
- ik: feasibility per (robot, tabletop grip, retraction set) at the five poses (feasibility, feasibility_handx,
  feasibility_handxworldz, feasibility_worlda, feasibility_worldaworldz); a grip enters the regrasp graph when
  all five hold. Extra columns hold the joint vectors (jnt_grasp, jnt_handx, jnt_handxworldz, jnt_worlda,
  jnt_worldaworldz, in robot.joint_names order; NULL where infeasible) and idscene.

Extra tables
- paramset(idparamset, stage, digest, params, idobject, created): every stage run's parameters (JSON) and
  the inputs they apply to; a stage's rows reference it, and a re-run with the same digest reuses them.
- gripper(idgripper, name, urdf, jaw_min, jaw_max, digest, collision_vertices, collision_faces, body_faces): the
  collision mesh (hand body and both fingers at full opening, in the TCP frame) lets checkers rebuild the hand
  without the library; its first body_faces faces are the hand body, the rest the fingers.
- scene(idscene, name, table_pose, table_size, ...): where the table sits in the world for IK.
- catalog_unit(digest, kind, part, robot, chunk, ids, status, error, counts, seconds, ...): the units of a
  `workbench catalog` build, created by `store.catalog` in catalogue stores (documented there).
- workbench_meta(key, value): the store's identity, written with the schema at creation: application
  ('regrasp-workbench') and schema_version (workbench.store.identity.SCHEMA_VERSION). A file without it is a
  schema-1 store when its tables are ours (upgraded in place), else another program's (refused, nothing written).
- stagedone(stage, runkey, rows, finished): completion of a stage written in several transactions (the IK stage,
  chunk by chunk; runkey names its tabletop set, robot, scene and retractions). A stage written in one
  transaction is complete when its paramset row exists. Consumers refuse an incomplete IK run unless asked.
- plan rows are unique per query and motions: a re-run of the same query with the same motion settings finds the
  stored answer (store.wan_harada.find_plan); another --acc or --speed, or motions timed otherwise, is a new plan.
- a task's plan (the grasp-placement table's Fig. 1 task) keeps its task: plan.start_held and plan.end_held (the
  motions begin with the part already in the hand / end with it still held), plan.insertion (unit world
  direction, NULL without one) and plan.insertion_depth (m), plan.obstacles (digest of the obstacles, NULL without
  any: the same query among other obstacles is another plan), planstep.lift (the TCP's world move from the grasp
  to the worlda pose: the insertion run backwards; NULL: straight up by worlda).
- planobstacle(idplanobstacle, idplan, seq, task_end, name, vertices, faces, pose): each obstacle fixed in the world
  that a plan's motions were checked against: task_end 'pickup' or 'destination', the mesh in metres in its own
  frame, pose its world pose (DOUBLE[16]); a validator reads them back with the plan.
"""

from __future__ import annotations

CORE_TABLES: tuple[str, ...] = (
    """CREATE TABLE IF NOT EXISTS object (
        idobject BIGINT PRIMARY KEY,
        name VARCHAR NOT NULL UNIQUE,
        digest VARCHAR NOT NULL,
        source VARCHAR,
        scale DOUBLE NOT NULL,
        com DOUBLE[3] NOT NULL,
        com_method VARCHAR NOT NULL,
        ntriangles BIGINT NOT NULL,
        vertices DOUBLE[3][] NOT NULL,
        faces INTEGER[3][] NOT NULL
    )""",
    """CREATE TABLE IF NOT EXISTS robot (
        idrobot BIGINT PRIMARY KEY,
        name VARCHAR NOT NULL UNIQUE,
        urdf VARCHAR NOT NULL,
        tcp_frame VARCHAR NOT NULL,
        tip_frame VARCHAR NOT NULL,
        mount DOUBLE[16] NOT NULL,
        base DOUBLE[16] NOT NULL,
        joint_names VARCHAR[] NOT NULL,
        locked VARCHAR NOT NULL DEFAULT '{}',
        drop_geometry VARCHAR[] NOT NULL DEFAULT [],
        digest VARCHAR NOT NULL
    )""",
    """CREATE TABLE IF NOT EXISTS gripper (
        idgripper BIGINT PRIMARY KEY,
        name VARCHAR NOT NULL,
        urdf VARCHAR,
        jaw_min DOUBLE NOT NULL,
        jaw_max DOUBLE NOT NULL,
        digest VARCHAR NOT NULL UNIQUE
    )""",
    """CREATE TABLE IF NOT EXISTS paramset (
        idparamset BIGINT PRIMARY KEY,
        stage VARCHAR NOT NULL,
        digest VARCHAR NOT NULL UNIQUE,
        params VARCHAR NOT NULL,
        idobject BIGINT REFERENCES object(idobject),
        created TIMESTAMP DEFAULT current_timestamp
    )""",
    """CREATE TABLE IF NOT EXISTS freeairgrip (
        idfreeairgrip BIGINT PRIMARY KEY,
        idobject BIGINT NOT NULL REFERENCES object(idobject),
        idparamset BIGINT NOT NULL REFERENCES paramset(idparamset),
        idgripper BIGINT NOT NULL REFERENCES gripper(idgripper),
        contactpoint0 DOUBLE[3] NOT NULL,
        contactpoint1 DOUBLE[3] NOT NULL,
        contactnormal0 DOUBLE[3] NOT NULL,
        contactnormal1 DOUBLE[3] NOT NULL,
        rotmat DOUBLE[16] NOT NULL,
        jawwidth DOUBLE NOT NULL,
        idfacet0 BIGINT,
        idfacet1 BIGINT,
        idcontactpair BIGINT,
        rotation DOUBLE,
        padoffset0 DOUBLE[2],
        padoffset1 DOUBLE[2],
        robustness DOUBLE
    )""",
    """CREATE TABLE IF NOT EXISTS freetabletopplacement (
        idfreetabletopplacement BIGINT PRIMARY KEY,
        idobject BIGINT NOT NULL REFERENCES object(idobject),
        idparamset BIGINT NOT NULL REFERENCES paramset(idparamset),
        rotmat DOUBLE[16] NOT NULL,
        stability DOUBLE NOT NULL,
        support DOUBLE[3][],
        probability DOUBLE,
        rocking BOOLEAN
    )""",
    """CREATE TABLE IF NOT EXISTS freetabletopgrip (
        idfreetabletopgrip BIGINT PRIMARY KEY,
        idfreetabletopplacement BIGINT NOT NULL REFERENCES freetabletopplacement(idfreetabletopplacement),
        idfreeairgrip BIGINT NOT NULL REFERENCES freeairgrip(idfreeairgrip),
        contactpoint0 DOUBLE[3] NOT NULL,
        contactpoint1 DOUBLE[3] NOT NULL,
        contactnormal0 DOUBLE[3] NOT NULL,
        contactnormal1 DOUBLE[3] NOT NULL,
        rotmat DOUBLE[16] NOT NULL,
        jawwidth DOUBLE NOT NULL
    )""",
    """CREATE TABLE IF NOT EXISTS angle (
        idangle BIGINT PRIMARY KEY,
        value DOUBLE NOT NULL UNIQUE
    )""",
    """CREATE TABLE IF NOT EXISTS tabletopplacements (
        idtabletopplacements BIGINT PRIMARY KEY,
        idfreetabletopplacement BIGINT NOT NULL REFERENCES freetabletopplacement(idfreetabletopplacement),
        idangle BIGINT NOT NULL REFERENCES angle(idangle),
        idparamset BIGINT NOT NULL REFERENCES paramset(idparamset),
        tabletopposition DOUBLE[3] NOT NULL,
        rotmat DOUBLE[16] NOT NULL
    )""",
    """CREATE TABLE IF NOT EXISTS tabletopgrips (
        idtabletopgrips BIGINT PRIMARY KEY,
        idtabletopplacements BIGINT NOT NULL REFERENCES tabletopplacements(idtabletopplacements),
        idfreeairgrip BIGINT NOT NULL REFERENCES freeairgrip(idfreeairgrip),
        idfreetabletopgrip BIGINT REFERENCES freetabletopgrip(idfreetabletopgrip),
        contactpoint0 DOUBLE[3] NOT NULL,
        contactpoint1 DOUBLE[3] NOT NULL,
        contactnormal0 DOUBLE[3] NOT NULL,
        contactnormal1 DOUBLE[3] NOT NULL,
        rotmat DOUBLE[16] NOT NULL,
        jawwidth DOUBLE NOT NULL
    )""",
    """CREATE TABLE IF NOT EXISTS ikret (
        idikret BIGINT PRIMARY KEY,
        handx DOUBLE NOT NULL,
        worldz DOUBLE NOT NULL,
        worlda DOUBLE,
        UNIQUE (handx, worldz, worlda)
    )""",
    """CREATE TABLE IF NOT EXISTS scene (
        idscene BIGINT PRIMARY KEY,
        digest VARCHAR NOT NULL UNIQUE,
        params VARCHAR NOT NULL
    )""",
    """CREATE TABLE IF NOT EXISTS ik (
        idik BIGINT PRIMARY KEY,
        idrobot BIGINT NOT NULL REFERENCES robot(idrobot),
        idtabletopgrips BIGINT NOT NULL REFERENCES tabletopgrips(idtabletopgrips),
        idikret BIGINT NOT NULL REFERENCES ikret(idikret),
        idscene BIGINT NOT NULL REFERENCES scene(idscene),
        feasibility BOOLEAN NOT NULL,
        feasibility_handx BOOLEAN NOT NULL,
        feasibility_handxworldz BOOLEAN NOT NULL,
        feasibility_worlda BOOLEAN,
        feasibility_worldaworldz BOOLEAN,
        jnt_grasp DOUBLE[],
        jnt_handx DOUBLE[],
        jnt_handxworldz DOUBLE[],
        jnt_worlda DOUBLE[],
        jnt_worldaworldz DOUBLE[],
        UNIQUE (idrobot, idtabletopgrips, idikret, idscene)
    )""",
)

# Tables of other stages (five-finger contact clustering, regrasp plans) are defined in their own sections
# below and joined into ALL_TABLES; every statement is idempotent (CREATE ... IF NOT EXISTS).

ALL_TABLES: tuple[str, ...] = CORE_TABLES

# Regrasp plans (Section V): a plan is one answer of `workbench plan` (start and goal as placement, x, y, yaw;
# its rank among the alternatives; regrasp and transfer counts; time to connect and search), its steps in order
# (kind pick / transfer / regrasp / place, the grasp, the object pose and the TCP pose in the world, the roadmap
# rows when the step is on the grid, joint vectors for approach (handx), grasp and retract (handx + worldz)).
# Motions (CONVENTIONS.md, Plans and motions): plan.duration (s, the whole timed trajectory),
# plan.removed (roadmap nodes or start/goal grips removed because their motions failed before this plan was found),
# plan.t_motion (s spent planning and timing motions), plan.acc (the acceleration limits used, rad/s^2 per joint),
# plan.speed (the share of the URDF's joint velocity limits the motions were timed under; NULL read as 1);
# plansegment: one row per motion in order (seq): kind (approach, retract, transit, transfer, gripper), caption (the
# step it serves: pick, transfer, release, regrasp, place), step (planstep seq), holding (object in the hand), t0 (s
# from the plan's start), duration (s), method (tcp-line, line, rrtconnect, dwell), jaw (m) and its knots: t (s from
# the plan's start, as CONVENTIONS.md says; t[0] = t0; schema 2 counted them from the segment's start), q and qd
# (row-major K x n, robot.joint_names order, rad and rad/s).
# plan.planner names the planner that answered: 'wan_harada' (the roadmap planner; idtabletop its tabletop parameter
# set) or 'tournassoud' (the grasp-placement table, Tournassoud et al. 1987; idtabletop the `tournassoud.table`
# parameter set, its placements and grasps are `freetabletopplacement` / `freeairgrip` rows written for the plan, see
# store.tournassoud). Both go through the same plan validator.
# A task's plan (the grasp-placement table's Fig. 1 task): plan.start_held / plan.end_held (the motions begin with
# the part already in the hand at the first step's grasp / end with it still held at the last's), plan.insertion
# (the final insertion's world direction, unit; NULL without one) and plan.insertion_depth (m), plan.obstacles (a
# digest of its obstacles, NULL without any: a query among other obstacles is another plan); planstep.lift (the TCP's
# world move from the grasp to the worlda pose, DOUBLE[3]: the insertion run backwards; NULL: straight up by the
# retraction set's worlda); planobstacle: one row per obstacle fixed in the world (seq, task_end 'pickup' or
# 'destination', name, the mesh's vertices (m, its own frame) and faces, pose its world pose), which the motions
# were checked against and the validator checks again.
PLAN_TABLES: tuple[str, ...] = (
    """CREATE TABLE IF NOT EXISTS plan (
        idplan BIGINT PRIMARY KEY,
        idobject BIGINT NOT NULL REFERENCES object(idobject),
        idrobot BIGINT NOT NULL REFERENCES robot(idrobot),
        idscene BIGINT NOT NULL REFERENCES scene(idscene),
        idikret BIGINT NOT NULL REFERENCES ikret(idikret),
        idtabletop BIGINT NOT NULL REFERENCES paramset(idparamset),
        start_placement BIGINT NOT NULL REFERENCES freetabletopplacement(idfreetabletopplacement),
        start_xyyaw DOUBLE[3] NOT NULL,
        goal_placement BIGINT NOT NULL REFERENCES freetabletopplacement(idfreetabletopplacement),
        goal_xyyaw DOUBLE[3] NOT NULL,
        rank INTEGER NOT NULL,
        regrasps INTEGER NOT NULL,
        transfers INTEGER NOT NULL,
        t_connect DOUBLE,
        t_search DOUBLE,
        created TIMESTAMP DEFAULT current_timestamp
    )""",
    """CREATE TABLE IF NOT EXISTS planstep (
        idplanstep BIGINT PRIMARY KEY,
        idplan BIGINT NOT NULL REFERENCES plan(idplan),
        seq INTEGER NOT NULL,
        kind VARCHAR NOT NULL,
        idfreeairgrip BIGINT NOT NULL REFERENCES freeairgrip(idfreeairgrip),
        idfreetabletopplacement BIGINT NOT NULL REFERENCES freetabletopplacement(idfreetabletopplacement),
        idtabletopgrips BIGINT REFERENCES tabletopgrips(idtabletopgrips),
        position DOUBLE[3] NOT NULL,
        yaw DOUBLE NOT NULL,
        object DOUBLE[16] NOT NULL,
        tcp DOUBLE[16] NOT NULL,
        jawwidth DOUBLE NOT NULL,
        jnt_approach DOUBLE[] NOT NULL,
        jnt_grasp DOUBLE[] NOT NULL,
        jnt_retract DOUBLE[] NOT NULL,
        jnt_worlda DOUBLE[],
        jnt_worldaworldz DOUBLE[],
        UNIQUE (idplan, seq)
    )""",
    """CREATE TABLE IF NOT EXISTS plansegment (
        idplansegment BIGINT PRIMARY KEY,
        idplan BIGINT NOT NULL REFERENCES plan(idplan),
        seq INTEGER NOT NULL,
        kind VARCHAR NOT NULL,
        caption VARCHAR NOT NULL,
        step INTEGER NOT NULL,
        holding BOOLEAN NOT NULL,
        t0 DOUBLE NOT NULL,
        duration DOUBLE NOT NULL,
        method VARCHAR NOT NULL,
        jaw DOUBLE NOT NULL,
        t DOUBLE[] NOT NULL,
        q DOUBLE[] NOT NULL,
        qd DOUBLE[] NOT NULL,
        UNIQUE (idplan, seq)
    )""",
    """CREATE TABLE IF NOT EXISTS planobstacle (
        idplanobstacle BIGINT PRIMARY KEY,
        idplan BIGINT NOT NULL REFERENCES plan(idplan),
        seq INTEGER NOT NULL,
        task_end VARCHAR NOT NULL,
        name VARCHAR NOT NULL,
        vertices DOUBLE[3][] NOT NULL,
        faces INTEGER[3][] NOT NULL,
        pose DOUBLE[16] NOT NULL,
        UNIQUE (idplan, seq)
    )""",
)

ALL_TABLES = ALL_TABLES + PLAN_TABLES

# Five-finger regrasp by contact-point clustering (Phoka & Sudsang; workbench.store.fingers).
# Each stage's rows reference the paramset of its run (stage name in paramset.stage):
# - fingers.contacts (params: faces): fingermesh, the decimated mesh whose face centroids are the contact
#   points; fingercontact, T_O: one row per face, idx its index in T_O (and face in the mesh), position (m),
#   normal (inward unit).
# - fingers.roadmap (params: contacts paramset, k, mu, sides, seed, n_init, torque_scale): fingerroadmap, one summary row
#   (sigma of the affinity, #vertex, #edge, #CC, seconds of clustering and roadmap construction);
#   fingercluster, one row per cluster with its representative (T_R), k-means centre in U space and size;
#   fingermember, T_O's cluster of every contact with its row of U (embedding) and of E (distances to every
#   centre, by cluster label); fingergrasp, the vertices of R (four contacts, ascending idx) with their
#   connected component; fingeredge, the edges of R: grasp 0 becomes grasp 1 by lifting `idlifted` and
#   placing `idplaced`.
# - fingers.queries (params: roadmap paramset, samples, picks, queries, seed, algorithm3): fingerlocalstats, the
#   numbers of Table II; fingerquery, one row per query of Table III: start and goal grasps and the sequence
#   (a list of grasps, each four idfingercontact), how each end linked to R (roadmap, alg1, alg2, alg3) and
#   seconds; fingerupdate, one row per persistent Algorithm 3 update of R these queries made (seq orders the
#   updates of one roadmap), with T_G, the four contacts it made representatives; fingerupdategrasp, the
#   vertices it added to R. Loading a roadmap applies every stored update, so later queries reuse them.
FINGER_TABLES: tuple[str, ...] = (
    """CREATE TABLE IF NOT EXISTS fingermesh (
        idfingermesh BIGINT PRIMARY KEY,
        idobject BIGINT NOT NULL REFERENCES object(idobject),
        idparamset BIGINT NOT NULL UNIQUE REFERENCES paramset(idparamset),
        ntriangles BIGINT NOT NULL,
        vertices DOUBLE[3][] NOT NULL,
        faces INTEGER[3][] NOT NULL,
        com DOUBLE[3] NOT NULL,
        radius DOUBLE NOT NULL
    )""",
    """CREATE TABLE IF NOT EXISTS fingercontact (
        idfingercontact BIGINT PRIMARY KEY,
        idfingermesh BIGINT NOT NULL REFERENCES fingermesh(idfingermesh),
        idparamset BIGINT NOT NULL REFERENCES paramset(idparamset),
        idx INTEGER NOT NULL,
        position DOUBLE[3] NOT NULL,
        normal DOUBLE[3] NOT NULL,
        UNIQUE (idparamset, idx)
    )""",
    """CREATE TABLE IF NOT EXISTS fingerroadmap (
        idfingerroadmap BIGINT PRIMARY KEY,
        idparamset BIGINT NOT NULL UNIQUE REFERENCES paramset(idparamset),
        idobject BIGINT NOT NULL REFERENCES object(idobject),
        idcontacts BIGINT NOT NULL REFERENCES paramset(idparamset),
        sigma DOUBLE NOT NULL,
        nvertex BIGINT NOT NULL,
        nedge BIGINT NOT NULL,
        ncomponent BIGINT NOT NULL,
        seconds_clustering DOUBLE NOT NULL,
        seconds_roadmap DOUBLE NOT NULL
    )""",
    """CREATE TABLE IF NOT EXISTS fingercluster (
        idfingercluster BIGINT PRIMARY KEY,
        idparamset BIGINT NOT NULL REFERENCES paramset(idparamset),
        label INTEGER NOT NULL,
        idrepresentative BIGINT NOT NULL REFERENCES fingercontact(idfingercontact),
        center DOUBLE[] NOT NULL,
        size INTEGER NOT NULL,
        UNIQUE (idparamset, label)
    )""",
    """CREATE TABLE IF NOT EXISTS fingermember (
        idfingermember BIGINT PRIMARY KEY,
        idparamset BIGINT NOT NULL REFERENCES paramset(idparamset),
        idfingercontact BIGINT NOT NULL REFERENCES fingercontact(idfingercontact),
        idfingercluster BIGINT NOT NULL REFERENCES fingercluster(idfingercluster),
        embedding DOUBLE[] NOT NULL,
        distances DOUBLE[] NOT NULL
    )""",
    """CREATE TABLE IF NOT EXISTS fingergrasp (
        idfingergrasp BIGINT PRIMARY KEY,
        idparamset BIGINT NOT NULL REFERENCES paramset(idparamset),
        idcontact0 BIGINT NOT NULL REFERENCES fingercontact(idfingercontact),
        idcontact1 BIGINT NOT NULL REFERENCES fingercontact(idfingercontact),
        idcontact2 BIGINT NOT NULL REFERENCES fingercontact(idfingercontact),
        idcontact3 BIGINT NOT NULL REFERENCES fingercontact(idfingercontact),
        component INTEGER NOT NULL
    )""",
    """CREATE TABLE IF NOT EXISTS fingeredge (
        idfingeredge BIGINT PRIMARY KEY,
        idparamset BIGINT NOT NULL REFERENCES paramset(idparamset),
        idfingergrasp0 BIGINT NOT NULL REFERENCES fingergrasp(idfingergrasp),
        idfingergrasp1 BIGINT NOT NULL REFERENCES fingergrasp(idfingergrasp),
        idlifted BIGINT NOT NULL REFERENCES fingercontact(idfingercontact),
        idplaced BIGINT NOT NULL REFERENCES fingercontact(idfingercontact)
    )""",
    """CREATE TABLE IF NOT EXISTS fingerlocalstats (
        idfingerlocalstats BIGINT PRIMARY KEY,
        idparamset BIGINT NOT NULL UNIQUE REFERENCES paramset(idparamset),
        idroadmap BIGINT NOT NULL REFERENCES paramset(idparamset),
        samples BIGINT NOT NULL,
        alg1_run DOUBLE NOT NULL,
        alg1_connect INTEGER NOT NULL,
        alg1_picked INTEGER NOT NULL,
        alg2_run DOUBLE NOT NULL,
        alg2_connect INTEGER NOT NULL,
        alg2_picked INTEGER NOT NULL,
        alg3_connect INTEGER NOT NULL,
        alg3_picked INTEGER NOT NULL
    )""",
    """CREATE TABLE IF NOT EXISTS fingerquery (
        idfingerquery BIGINT PRIMARY KEY,
        idparamset BIGINT NOT NULL REFERENCES paramset(idparamset),
        idroadmap BIGINT NOT NULL REFERENCES paramset(idparamset),
        seq INTEGER NOT NULL,
        start BIGINT[] NOT NULL,
        goal BIGINT[] NOT NULL,
        connected BOOLEAN NOT NULL,
        start_method VARCHAR NOT NULL,
        goal_method VARCHAR NOT NULL,
        seconds DOUBLE NOT NULL,
        sequence BIGINT[][],
        UNIQUE (idparamset, seq)
    )""",
    """CREATE TABLE IF NOT EXISTS fingerupdate (
        idfingerupdate BIGINT PRIMARY KEY,
        idroadmap BIGINT NOT NULL REFERENCES paramset(idparamset),
        idqueries BIGINT NOT NULL REFERENCES paramset(idparamset),
        seq INTEGER NOT NULL,
        tg BIGINT[] NOT NULL,
        UNIQUE (idroadmap, seq)
    )""",
    """CREATE TABLE IF NOT EXISTS fingerupdategrasp (
        idfingerupdategrasp BIGINT PRIMARY KEY,
        idfingerupdate BIGINT NOT NULL REFERENCES fingerupdate(idfingerupdate),
        idcontact0 BIGINT NOT NULL REFERENCES fingercontact(idfingercontact),
        idcontact1 BIGINT NOT NULL REFERENCES fingercontact(idfingercontact),
        idcontact2 BIGINT NOT NULL REFERENCES fingercontact(idfingercontact),
        idcontact3 BIGINT NOT NULL REFERENCES fingercontact(idfingercontact)
    )""",
)

ALL_TABLES = ALL_TABLES + FINGER_TABLES

# Simulation (CONVENTIONS.md, Simulation): a plan replayed in MuJoCo (workbench.simulation). simulation: one row per
# plan and digest of every simulation parameter (params: their JSON, the defaults resolved: grip force, pad and
# table friction, timestep, density, tolerances, the convex decomposition's settings); confirmed, and else the
# first failure: failure (shove, slip, drop, roll, pose, goal), failure_step (planstep seq), failure_t (s from the
# plan's start), message; final_error (m) and final_angle (rad) against the goal; simulated (s of physics), seconds
# (s of stepping), hulls (convex parts of the part); playback_t (s) and playback_pose (4x4 row-major per sample, the
# simulated part's pose for the animation). simulationstep: one row per waypoint (the end of each plansegment, seq
# as there): step (planstep seq), kind and caption of the motion, t (s), planned and simulated part poses
# (DOUBLE[16]), error (m, of the centre of mass) and angle (rad), slip and slip_angle (largest motion of the part in
# the hand since the close, NULL when not held), settle (s after a release until the part rests, NULL otherwise),
# touching (a pad touches the part), ok (within the waypoint tolerances).
SIMULATION_TABLES: tuple[str, ...] = (
    """CREATE TABLE IF NOT EXISTS simulation (
        idsimulation BIGINT PRIMARY KEY,
        idplan BIGINT NOT NULL REFERENCES plan(idplan),
        digest VARCHAR NOT NULL,
        params VARCHAR NOT NULL,
        confirmed BOOLEAN NOT NULL,
        failure VARCHAR,
        failure_step INTEGER,
        failure_t DOUBLE,
        message VARCHAR,
        final_error DOUBLE,
        final_angle DOUBLE,
        simulated DOUBLE,
        seconds DOUBLE,
        hulls INTEGER,
        playback_t DOUBLE[],
        playback_pose DOUBLE[][],
        created TIMESTAMP DEFAULT current_timestamp,
        UNIQUE (idplan, digest)
    )""",
    """CREATE TABLE IF NOT EXISTS simulationstep (
        idsimulationstep BIGINT PRIMARY KEY,
        idsimulation BIGINT NOT NULL REFERENCES simulation(idsimulation),
        seq INTEGER NOT NULL,
        step INTEGER,
        kind VARCHAR,
        caption VARCHAR,
        t DOUBLE,
        planned DOUBLE[16],
        simulated DOUBLE[16],
        error DOUBLE,
        angle DOUBLE,
        slip DOUBLE,
        slip_angle DOUBLE,
        settle DOUBLE,
        touching BOOLEAN,
        ok BOOLEAN,
        UNIQUE (idsimulation, seq)
    )""",
)

ALL_TABLES = ALL_TABLES + SIMULATION_TABLES

# Columns added after a store format was first released; run after the CREATE statements so older files gain them.
MIGRATIONS: tuple[str, ...] = (
    "ALTER TABLE freeairgrip ADD COLUMN IF NOT EXISTS padoffset0 DOUBLE[2]",
    "ALTER TABLE freeairgrip ADD COLUMN IF NOT EXISTS padoffset1 DOUBLE[2]",
    "ALTER TABLE freeairgrip ADD COLUMN IF NOT EXISTS robustness DOUBLE",
    "ALTER TABLE robot ADD COLUMN IF NOT EXISTS locked VARCHAR DEFAULT '{}'",
    "ALTER TABLE robot ADD COLUMN IF NOT EXISTS drop_geometry VARCHAR[] DEFAULT []",
    "ALTER TABLE robot ADD COLUMN IF NOT EXISTS package_dirs VARCHAR[] DEFAULT []",
    "ALTER TABLE paramset ADD COLUMN IF NOT EXISTS used BIGINT DEFAULT 0",
    "ALTER TABLE robot ADD COLUMN IF NOT EXISTS idgripper BIGINT",
    "ALTER TABLE gripper ADD COLUMN IF NOT EXISTS collision_vertices DOUBLE[][]",
    "ALTER TABLE gripper ADD COLUMN IF NOT EXISTS collision_faces INTEGER[][]",
    # the lift retractions: ik rows computed before them lack two of the five poses; they are dropped so
    # the next `workbench ik` run computes them again, and their retraction set gets the default worlda
    "ALTER TABLE ikret ADD COLUMN IF NOT EXISTS worlda DOUBLE",
    "ALTER TABLE ik ADD COLUMN IF NOT EXISTS feasibility_worlda BOOLEAN",
    "ALTER TABLE ik ADD COLUMN IF NOT EXISTS feasibility_worldaworldz BOOLEAN",
    "ALTER TABLE ik ADD COLUMN IF NOT EXISTS jnt_worlda DOUBLE[]",
    "ALTER TABLE ik ADD COLUMN IF NOT EXISTS jnt_worldaworldz DOUBLE[]",
    "DELETE FROM ik WHERE feasibility_worlda IS NULL OR feasibility_worldaworldz IS NULL",
    "UPDATE ikret SET worlda = 0.05 WHERE worlda IS NULL",
    "ALTER TABLE planstep ADD COLUMN IF NOT EXISTS jnt_worlda DOUBLE[]",
    "ALTER TABLE planstep ADD COLUMN IF NOT EXISTS jnt_worldaworldz DOUBLE[]",
    "ALTER TABLE gripper ADD COLUMN IF NOT EXISTS body_faces INTEGER",
    "ALTER TABLE robot ADD COLUMN IF NOT EXISTS allowed_pairs VARCHAR",
    "ALTER TABLE plan ADD COLUMN IF NOT EXISTS duration DOUBLE",
    "ALTER TABLE plan ADD COLUMN IF NOT EXISTS removed INTEGER",
    "ALTER TABLE plan ADD COLUMN IF NOT EXISTS t_motion DOUBLE",
    "ALTER TABLE freetabletopplacement ADD COLUMN IF NOT EXISTS probability DOUBLE",
    "ALTER TABLE freetabletopplacement ADD COLUMN IF NOT EXISTS rocking BOOLEAN",
    "ALTER TABLE plan ADD COLUMN IF NOT EXISTS acc DOUBLE[]",
    "ALTER TABLE plan ADD COLUMN IF NOT EXISTS speed DOUBLE",
    # the planner that answered: 'wan_harada' (the roadmap planner, every plan stored before) or 'tournassoud'
    "ALTER TABLE plan ADD COLUMN IF NOT EXISTS planner VARCHAR DEFAULT 'wan_harada'",
    # a task's plan: the part in the hand at the start or the end, the insertion, the obstacles; the held part's lift
    "ALTER TABLE plan ADD COLUMN IF NOT EXISTS start_held BOOLEAN DEFAULT false",
    "ALTER TABLE plan ADD COLUMN IF NOT EXISTS end_held BOOLEAN DEFAULT false",
    "ALTER TABLE plan ADD COLUMN IF NOT EXISTS insertion DOUBLE[3]",
    "ALTER TABLE plan ADD COLUMN IF NOT EXISTS insertion_depth DOUBLE",
    "ALTER TABLE plan ADD COLUMN IF NOT EXISTS obstacles VARCHAR",
    "ALTER TABLE planstep ADD COLUMN IF NOT EXISTS lift DOUBLE[3]",
)
