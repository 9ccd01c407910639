// REST through UnityWebRequest: call it from the main thread (Unity's rule for
// UnityWebRequest); the task completes on the main thread when the request is done.
using System.Collections.Generic;
using System.Text;
using System.Threading.Tasks;
using UnityEngine.Networking;

namespace PhantomTouch
{
    public sealed class UnityWebRequestTransport : IHttpTransport
    {
        /// <summary>Longest a request may take, s.</summary>
        public int TimeoutS = 10;

        public Task<HttpAnswer> SendAsync(string method, string url, string jsonBody, IDictionary<string, string> headers)
        {
            var request = new UnityWebRequest(url, method);
            request.downloadHandler = new DownloadHandlerBuffer();
            if (jsonBody != null)
            {
                request.uploadHandler = new UploadHandlerRaw(Encoding.UTF8.GetBytes(jsonBody));
                request.SetRequestHeader("Content-Type", "application/json");
            }
            foreach (var header in headers) request.SetRequestHeader(header.Key, header.Value);
            request.timeout = TimeoutS;
            var done = new TaskCompletionSource<HttpAnswer>();
            var operation = request.SendWebRequest();
            operation.completed += _ =>
            {
                var answer = new HttpAnswer();
                if (request.result == UnityWebRequest.Result.ConnectionError)
                {
                    answer.Error = request.error;
                }
                else
                {
                    answer.Status = (int)request.responseCode;
                    answer.Body = request.downloadHandler.data ?? new byte[0];
                }
                request.Dispose();
                done.SetResult(answer);
            };
            return done.Task;
        }
    }
}
