#!/usr/bin/env python3
"""Writes scenes/leach_*.json: Leach & Marais' three test scenarios (section 6.3), each as a small
scene for a 2-core machine and a "_paper" variant at the paper's sizes (docs/stress.md says how the
sizes scale and what was measured). Run from anywhere: python3 scripts/make_leach_scenes.py [DIR]
(DIR: where to write them, default scenes/; tests/apps/scenarios_test.cpp writes them to a
temporary folder and checks that they are the shipped files).
"""
import json
import os
import sys

SCENES = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "scenes")
def mat(r, k=2.0e4, e=0.3, unloading=None):
    # the small variants' sand follows docs/calibration.md for bodies that land and must stay
    # (hysteretic spring, unloading_stiffness_ratio 9 with a weak dashpot); the paper variants
    # keep the linear spring-dashpot
    m = {"name":"sand","density":2650.0,"friction":0.5,"restitution":e}
    if unloading: m["unloading_stiffness_ratio"] = unloading
    m.update({"stiffness":k,"tangential_stiffness_ratio":0.2857142857142857,"granule_radius":r,"packing_fraction":0.6})
    return [m]
# The paper variants run without a frame budget: the paper's sizes, whatever they cost.
PAPER = "at paper size (GPU machines; no frame budget: the paper's sizes, whatever they cost): "
def terrain(samples, size, soil=0.6, kind="flat"):
    src={"type":"procedural","kind":"flat","height":0.0,"samples_x":samples,"samples_z":samples}
    return {"source":src,"size":[size,size],"origin":[-size/2,0.0,-size/2],"soil_depth":soil,"material":"sand"}
def write(path, s):
    open(path,'w').write(json.dumps(s, indent=2)+"\n")

# --- 1: one large particle system, a barrel dropped on it
def s1(paper):
    r = 0.0094 if paper else 0.035
    return {"version":1,
      "name":"leach_1_barrel" + ("_paper" if paper else ""),
      "description":("Leach & Marais 6.3, scenario 1 " + PAPER + "one patch of about 140,000 granules "
                     "(560,000 spheres, measured: 139,554; the paper: 115,502) under a 100 kg barrel dropped from 2 m. Granule radius 9.4 mm, the only change from the small variant."
                     if paper else
                     "Leach & Marais 6.3, scenario 1 sized for a 2-core machine: one patch of 2,214 granules "
                     "(granule radius 3.5 cm) under a 100 kg barrel (cylinder r 0.3 m, h 0.9 m) dropped from 2 m. The paper variant is leach_1_barrel_paper.json."),
      "terrain":terrain(129,64.0,0.5),
      "materials":(mat(r, 1.0e4, 0.2) if paper else mat(r, 1.0e5, 0.58, 9.0)),
      "bodies":[{"name":"barrel","shape":{"type":"cylinder","radius":0.3,"height":0.9},"mass":100.0,
                 "pose":{"position":[0.0,2.45,0.0]},"friction":0.6,"restitution":0.1}],
      "simulation":{**({"frame_budget_ms":"off"} if paper else {}),
                    "dt":1/240,"substeps":1,"duration":(10.0 if paper else 2.0),"backend":("gl" if paper else "cpu"),
                    "pool":({"slots":1,"granules_per_slot":163840,"shell_spheres_per_slot":16384} if paper else
                            {"slots":1,"granules_per_slot":8192}),
                    "sleep":{"speed_threshold":0.01,"hold_time":1.0},"idle_timeout":120.0},
      "cameras":[{"name":"side","position":[3.0,1.5,3.0],"target":[0.0,0.3,0.0],"fov_deg":40.0,"width":800,"height":600}],
      "outputs":{"report":True}}

# --- 2: three simulations at three distances from the camera (one granule size: see description)
def s2(paper):
    r = 0.024 if paper else 0.06
    # the same crate at 3, 23 and 35 m from the camera; the patch under each takes the particle
    # scale of its distance band (simulation.scale_by_distance), as in the paper
    crate = lambda name, z: {"name":name,"restitution":0.2,"shape":{"type":"box","half_extents":[2.5,0.3,2.5]},"mass":2000.0,
                             "pose":{"position":[0.0,1.5,z]}}
    bodies=[crate("near_crate", 8.0), crate("mid_crate", -12.0), crate("far_crate", -24.0)]
    common = ("three simulations at three particle scales at three distances from the camera. "
              "The same 2 t crate lands 3, 23 and 35 m from the camera; simulation.scale_by_distance gives the patch under it particle scale 1, 1.59 and 2")
    return {"version":1,
      "name":"leach_2_three_scales" + ("_paper" if paper else ""),
      "description":("Leach & Marais 6.3, scenario 2 " + PAPER + common +
                     ": 51,710 / 11,880 / 6,125 granules (measured) "
                     "(the paper: 202,352 / 54,876 / 25,776 particles = 50,588 / 13,719 / 6,444 granules)."
                     if paper else
                     "Leach & Marais 6.3, scenario 2 sized for a 2-core machine: " + common +
                     " (granule radius 6, 9.5 and 12 cm in the world): 4,078 / 810 / 639 granules (measured, sandpatch run). "
                     "The paper variant is leach_2_three_scales_paper.json."),
      "terrain":terrain(257,64.0,0.6),
      "materials":(mat(r, 2.0e4) if paper else mat(r, 5.0e4, 0.9, 9.0)),
      "bodies":bodies,
      "simulation":{**({"frame_budget_ms":"off"} if paper else {}),
                    "dt":1/120,"substeps":1,"duration":(20.0 if paper else 1.5),"backend":("gl" if paper else "cpu"),
                    "pool":({"slots":3,"granules_per_slot":65536,"shell_spheres_per_slot":65536} if paper else
                            {"slots":3,"granules_per_slot":8192}),
                    "scale_by_distance":{"camera":"main","bands":[{"max_distance":10.0,"particle_scale":1.0},
                                                                 {"max_distance":30.0,"particle_scale":1.59},
                                                                 {"max_distance":1000.0,"particle_scale":2.0}]},
                    "sleep":{"speed_threshold":0.01,"hold_time":1.0},"idle_timeout":120.0},
      "cameras":[{"name":"main","position":[0.0,2.5,11.0],"target":[0.0,0.0,-12.0],"fov_deg":50.0,"width":1280,"height":720}],
      "outputs":{"report":True}}

# --- 3: ten simulations, bodies arriving one after the other, each sleeping at rest
def s3(paper):
    interval = 10.0 if paper else 2.0
    r = 0.0366 if paper else 0.08
    scale = 0.33 if paper else 1.0
    bodies=[]
    for k in range(10):
        x = -20.0 + (k % 5) * 10.0
        z = -5.0 if k < 5 else 5.0
        # sizes vary so patches hold 55,000-75,000 granules at paper size (side 2.5 .. 2.9 m)
        rad = 0.25 + 0.02 * k
        bodies.append({"name":"ball_%d" % k,"restitution":0.2,"shape":{"type":"sphere","radius":round(rad,3)},"density":800.0,
                       "pose":{"position":[x,1.0 + rad,z]},"spawn_time":k*interval})
    return {"version":1,
      "name":"leach_3_ten_bodies" + ("_paper" if paper else ""),
      "description":("Leach & Marais 6.3, scenario 3 " + PAPER + "ten simulations of about 55,000-75,000 granules at particle scale 0.33, "
                     "a body arriving every 10 s; each patch sleeps when at rest (the first ball's: 83,472 granules, measured)." if paper else
                     "Leach & Marais 6.3, scenario 3 sized for a 2-core machine: ten simulations of 464 granules each (radius 8 cm), a body arriving every 2 s "
                     "instead of 10 s; each patch sleeps when at rest (0.02 m/s for 0.5 s). The paper variant is leach_3_ten_bodies_paper.json."),
      "terrain":terrain(129,64.0,0.6),
      "materials":(mat(r, 2.0e4) if paper else mat(r, 8.0e4, 0.9, 9.0)),
      "bodies":bodies,
      "simulation":{**({"frame_budget_ms":"off"} if paper else {}),
                    "dt":1/120,"substeps":1,"duration":(10*interval + 10.0),"backend":("gl" if paper else "cpu"),
                    "particle_scale":scale,
                    "pool":{"slots":10,"granules_per_slot":(98304 if paper else 4096)},
                    "sleep":({"speed_threshold":0.01,"hold_time":1.0} if paper else {"speed_threshold":0.02,"hold_time":0.5}),
                    "idle_timeout":120.0},
      "cameras":[{"name":"above","position":[0.0,25.0,30.0],"target":[0.0,0.0,0.0],"fov_deg":50.0,"width":1280,"height":720}],
      "outputs":{"report":True}}

for f,p in ((s1,False),(s1,True),(s2,False),(s2,True),(s3,False),(s3,True)):
    s=f(p); write(os.path.join(SCENES, "%s.json" % s["name"]), s)
