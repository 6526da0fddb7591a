"""Two CPU processes with the gloo backend train one step each with DistributedDataParallel: same weights after."""
from pathlib import Path

import torch
import torch.multiprocessing as mp

from dcslam.depth.train import TrainConfig
from dcslam.stages.train import train
from tests.fixtures import depth as depth_fixtures


def _worker(rank, world, init_file, ws, out):
    import torch.distributed as dist

    torch.set_num_threads(1)
    dist.init_process_group("gloo", init_method=f"file://{init_file}", rank=rank, world_size=world)
    try:
        drives = Path(ws) / "drives"
        config = TrainConfig(train_drives=[drives / "drive_a.h5", drives / "drive_b.h5"], val_drives=[],
                             model_hparams={"channels": 4}, batch_size=3, max_frames=3, device="cpu", seed=rank)
        result = train(Path(ws) / "runs" / "ddp", config)
        torch.save({k: v.detach().clone() for k, v in result.model.state_dict().items()}, f"{out}/rank{rank}.pt")
    finally:
        dist.destroy_process_group()


def test_two_gloo_processes_hold_identical_weights(tmp_path):
    ws = depth_fixtures.write_workspace(tmp_path / "ws", n=3)
    mp.spawn(_worker, args=(2, str(tmp_path / "init"), str(ws), str(tmp_path)), nprocs=2, join=True)
    a = torch.load(tmp_path / "rank0.pt", weights_only=True)
    b = torch.load(tmp_path / "rank1.pt", weights_only=True)
    torch.manual_seed(0)
    from dcslam.depth.models import build_model

    initial = build_model("sparse-conv", channels=4).state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)  # identical on both ranks (seeds differ: DDP broadcast + allreduce)
    assert any(not torch.equal(a[k], initial[k]) for k in a)  # and a step was taken
    assert (ws / "runs" / "ddp" / "model.pt").exists()
