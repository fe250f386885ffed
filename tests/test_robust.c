/* Robustness: interrupted runs stop promptly with 130/143 and leave no partial or temporary
 * file; impossible requests fail early with exit 4; every exit-code class from the CLI. */
#include "bn_test.h"

#include <dirent.h>
#include <signal.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

/* A closed box with reflectance 0.9999: Jacobi needs ~1e5 sweeps, so a solve runs long. */
static const char *write_slow_box(void)
{
    const char *obj = bn_test_tmp("box.obj");
    FILE *fp = fopen(obj, "w");
    BN_ASSERT(fp != NULL);
    fprintf(fp, "mtllib box.mtl\nusemtl m\n"
                "v 1 0 0\nv 0 0 0\nv 0 0 1\nv 1 0 1\nf -4 -3 -2 -1\n"
                "v 1 1 0\nv 1 1 1\nv 0 1 1\nv 0 1 0\nf -4 -3 -2 -1\n"
                "v 0 0 1\nv 0 0 0\nv 0 1 0\nv 0 1 1\nf -4 -3 -2 -1\n"
                "v 1 0 0\nv 1 0 1\nv 1 1 1\nv 1 1 0\nf -4 -3 -2 -1\n"
                "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf -4 -3 -2 -1\n"
                "v 1 0 1\nv 0 0 1\nv 0 1 1\nv 1 1 1\nf -4 -3 -2 -1\n");
    fclose(fp);
    fp = fopen(bn_test_tmp("box.mtl"), "w");
    fprintf(fp, "newmtl m\nKd 0.9999 0.9999 0.9999\nKe 1 1 1\n");
    fclose(fp);
    return obj;
}

/* Lists the files in the test's folder other than the inputs; returns how many. */
static int stray_files(const char *const *inputs, int ninputs, char *names, size_t cap)
{
    DIR *d = opendir(bn_test_tmpdir());
    struct dirent *e;
    int n = 0;
    names[0] = '\0';
    while ((e = readdir(d)) != NULL) {
        int input = e->d_name[0] == '.' && (e->d_name[1] == '\0' || (e->d_name[1] == '.' && e->d_name[2] == '\0'));
        for (int i = 0; i < ninputs && !input; i++)
            input = strcmp(e->d_name, inputs[i]) == 0;
        if (input)
            continue;
        n++;
        strncat(names, e->d_name, cap - strlen(names) - 2);
        strncat(names, " ", cap - strlen(names) - 1);
    }
    closedir(d);
    return n;
}

/* Runs bounce with argv in the test folder, sends `sig` after `delay` seconds, returns the exit code
 * and the seconds between the signal and the exit. */
static int run_and_signal(char *const argv[], int sig, double delay, double *stop_seconds)
{
    pid_t pid = fork();
    int status;
    struct timespec t0, t1, ts = {(time_t)delay, (long)((delay - (double)(time_t)delay) * 1e9)};
    BN_ASSERT(pid >= 0);
    if (pid == 0) {
        if (chdir(bn_test_tmpdir()) != 0)
            _exit(99);
        freopen("/dev/null", "w", stdout);
        execv(bn_test_bounce_exe(), argv);
        _exit(98);
    }
    nanosleep(&ts, NULL);
    BN_ASSERT_EQ(waitpid(pid, &status, WNOHANG), 0);   /* still running: the run is long enough */
    clock_gettime(CLOCK_MONOTONIC, &t0);
    kill(pid, sig);
    BN_ASSERT_EQ(waitpid(pid, &status, 0), pid);
    clock_gettime(CLOCK_MONOTONIC, &t1);
    *stop_seconds = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
    if (WIFSIGNALED(status))
        BN_FAIL("bounce was killed by signal %d instead of stopping cleanly", WTERMSIG(status));
    return WEXITSTATUS(status);
}

BN_TEST(interrupt_solve_sigterm)
{
    const char *inputs[] = {"box.obj", "box.mtl"};
    char *argv[] = {"bounce", "solve", "box.obj", "--patches", "300", "--method", "jacobi", "--tol", "1e-15",
                    "--max-iter", "100000000", "--precision", "double", "--log", "conv.csv", "-o", "patches.csv",
                    "-q", NULL};
    char stray[1024];
    double stop;
    write_slow_box();
    BN_ASSERT_EQ(run_and_signal(argv, SIGTERM, 2.0, &stop), 143);
    BN_ASSERT_LT(stop, 5.0);   /* promptly */
    if (stray_files(inputs, 2, stray, sizeof stray))
        BN_FAIL("files left behind after SIGTERM: %s", stray);
}

BN_TEST(interrupt_formfactors_sigint)
{
    char *argv[] = {"bounce", "formfactors", NULL, "--unit", "mm", "--patches", "6000", "--samples", "64",
                    "-o", "F.csv", "-q", NULL};
    char stray[1024], scene[4096];
    double stop;
    snprintf(scene, sizeof scene, "%s/meshes/cornell-box.obj", bn_test_source_dir());
    argv[2] = scene;
    BN_ASSERT_EQ(run_and_signal(argv, SIGINT, 1.5, &stop), 130);
    BN_ASSERT_LT(stop, 5.0);
    if (stray_files(NULL, 0, stray, sizeof stray))
        BN_FAIL("files left behind after SIGINT: %s", stray);
}

BN_TEST(interrupt_trace_sigint)
{
    char *argv[] = {"bounce", "trace", NULL, "--unit", "mm", "--patches", "300", "--spp", "100000",
                    "--size", "256x256", "-o", "pt.exr", "--patches-out", "pt.csv", "-q", NULL};
    char stray[1024], scene[4096];
    double stop;
    snprintf(scene, sizeof scene, "%s/meshes/cornell-box.obj", bn_test_source_dir());
    argv[2] = scene;
    BN_ASSERT_EQ(run_and_signal(argv, SIGINT, 1.5, &stop), 130);
    BN_ASSERT_LT(stop, 5.0);
    if (stray_files(NULL, 0, stray, sizeof stray))
        BN_FAIL("files left behind after SIGINT: %s", stray);
}

/* Every exit-code class from the command line. */
BN_TEST(exit_code_classes)
{
    char args[8192], *out = NULL;
    const char *cornell = bn_test_path("meshes/cornell-box.obj");
    /* 2: usage */
    BN_ASSERT_EQ(bn_test_bounce("solve --tol", &out), 2);
    free(out);
    /* 3: bad input */
    snprintf(args, sizeof args, "solve '%s' -o '%s'", bn_test_path("tests/corpus/nan-coordinate.obj"),
             bn_test_tmp("p.csv"));
    BN_ASSERT_EQ(bn_test_bounce(args, &out), 3);
    free(out);
    /* 4: resource limit, before any work: 10 million patches with dense F (364 TiB), refused from the
     * faces' sizes before meshing (a million took 12 s to mesh before the refusal) */
    snprintf(args, sizeof args, "formfactors '%s' --unit mm --patches 10000000 -q", cornell);
    BN_ASSERT_EQ(bn_test_bounce(args, &out), 4);
    BN_ASSERT(strstr(out, "patches") && strstr(out, "--storage sparse"));
    free(out);
    /* the images' memory, refused before the scene is even read (32768^2 x 6 layers: 216 GiB) */
    snprintf(args, sizeof args, "bounces '%s' --unit mm --size 32768x32768 -o '%s' -q", cornell, bn_test_tmp("big.exr"));
    BN_ASSERT_EQ(bn_test_bounce(args, &out), 4);
    BN_ASSERT(strstr(out, "images of 32768x32768 pixels in 6 layers") != NULL);
    free(out);
    snprintf(args, sizeof args, "formfactors '%s' --unit mm --patches 400 --max-memory 1000 -q", cornell);
    BN_ASSERT_EQ(bn_test_bounce(args, &out), 4);
    free(out);
    /* 5: numerical: not converged within the iteration limit */
    snprintf(args, sizeof args, "solve '%s' --unit mm --patches 100 --method jacobi --max-iter 2 -o '%s' -q", cornell,
             bn_test_tmp("p.csv"));
    BN_ASSERT_EQ(bn_test_bounce(args, &out), 5);
    BN_ASSERT(!bn_test_file_exists(bn_test_tmp("p.csv")));
    free(out);
    /* 6: a failed verdict: Monte Carlo form factors with 4 samples against the tracer on the furnace */
    snprintf(args, sizeof args,
             "crosscheck '%s' --patches 24 --ff montecarlo --samples 4 --spp 256 -n 2 --disc none -q",
             bn_test_path("meshes/furnace-box.obj"));
    BN_ASSERT_EQ(bn_test_bounce(args, &out), 6);
    BN_ASSERT(strstr(out, "verdict: fail") != NULL);
    free(out);
}

/* A PLY face with a repeated vertex is dropped, and the face colours of the others are read by
 * bounce's own scan (OpenMesh writes out of bounds setting the colour of a face it refused). */
BN_TEST(ply_degenerate_face_with_colour)
{
    char args[4200], *out = NULL;
    snprintf(args, sizeof args, "info '%s' -q", bn_test_path("tests/data/ply-degenerate-face-with-colour.ply"));
    BN_ASSERT_EQ(bn_test_bounce(args, &out), 0);
    BN_ASSERT(strstr(out, "1 faces with a repeated vertex were dropped") != NULL);
    BN_ASSERT(strstr(out, "1 faces after validation") != NULL);
    BN_ASSERT(strstr(out, "1        0.502    0 ") != NULL);   /* (255, 128, 0) / 255 */
    free(out);
}
