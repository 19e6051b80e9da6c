// Damage zones (glsynth.appearance.materials.DamageZones): a damage material's maps apply only
// where the mesh-frame z lies in one of u_zone_count intervals (x: z0, y: z1, both included).
uniform vec2 u_zones[MAX_ZONES];  // #defined from materials.MAX_ZONES (gl.programs)
uniform int u_zone_count;

bool in_zones(float z) {
    bool inside = false;
    for (int i = 0; i < u_zone_count; ++i)
        inside = inside || (z >= u_zones[i].x && z <= u_zones[i].y);
    return inside;
}
